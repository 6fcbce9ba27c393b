#pragma once
// Tikhonov solutions of A·X ≈ b (Eq. 17 of Zhao 2019): X_λ = (AᵀA + λ²I)⁻¹Aᵀb, or in general
// form (AᵀA + λ²P)⁻¹Aᵀb with a penalty P = LᵀL (a smoothness prior) banded on the band unknowns
// and possibly coupled with the border.  AᵀA is formed once (from A's rows in band storage when
// they are narrow, else by cholmod_aat; upper triangle kept).  Narrow rows (the four-sensor
// systems): each λ is one banded LDLᵀ of the band block (src/core/band_ldlt.hpp, several times
// faster than CHOLMOD's simplicial LDLᵀ at a half-bandwidth of 7).  Otherwise the symbolic
// analysis (natural ordering, simplicial LDLᵀ) is done once and each λ is one CHOLMOD numeric
// factorisation with its shift β = λ² (Ceres-style: Tikhonov is a per-solve option, not a matrix
// edit).  This is the only place that talks to CHOLMOD (its C API, in tikhonov_solver.cpp).
//
// Read as a prior (x_band ~ N(0, σ²/λ²·P⁻¹), border flat), M = AᵀA + λ²P is the posterior
// precision in units of 1/σ²: log_det() and selected_inverse() give what a likelihood-based λ rule
// (REML) and the posterior covariance σ²M⁻¹ need, from the factor, in O(n·b²) for a band of
// half-width b (Takahashi's recurrence), without forming anything dense of size n.
//
// A sweep over λ can run on several threads: worker() gives another solver over the same A and
// AᵀA (shared, read-only) with its own factor (and CHOLMOD workspace on the general path).  Each
// solver object is used by one thread at a time.
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <memory>
#include <string>
#include <vector>

namespace errsep::core {

enum class SolverStatus {
  success,
  /// A pivot of the LDLᵀ factor came out zero, negative or not finite (TikhonovSolver::failure()
  /// says where and at which λ): the matrix is singular or indefinite to working precision.
  /// AᵀA + λ²P is positive semi-definite by construction, so for a penalty that is too this means
  /// the round-off of the factorisation exceeded its smallest eigenvalue (the digits are lost),
  /// or A is rank-deficient at λ = 0.  CHOLMOD's LDLᵀ stops only at an exactly zero pivot; a
  /// negative one it takes silently (log det NaN, a wrong solution), so every pivot is checked.
  not_positive_definite,
  analysis_failed,
  not_factorized,
};
const char* to_string(SolverStatus s);

/// Where and why the last factorisation failed (SolverStatus::not_positive_definite).
struct FactorFailure {
  double lambda = 0.0;
  Eigen::Index pivot = -1;    ///< 0-based, over all unknowns (the border's pivots come last)
  Eigen::Index unknowns = 0;  ///< n, for the message
  double pivot_value = 0.0;   ///< D at that pivot (0, negative or not finite)
  double diagonal = 0.0;      ///< the matrix's own diagonal entry there: the round-off's scale
  bool in_border = false;     ///< a pivot of the border's Schur complement
  bool stopped_by_cholmod = false;  ///< CHOLMOD stopped at it (an exactly zero pivot)
  /// "lambda = 5.62 rejected: factor not positive definite at pivot 51234 of 99997 (D = -3.1e-09,
  /// diagonal 401): ..." — what a λ search and a result's diagnostics carry.
  std::string message() const;
};

/// Entries of M⁻¹ (M = AᵀA + λ²P, or + λ²I) inside the band of the factor, and its border blocks:
/// what the posterior covariance of local quantities needs (Takahashi's selected inversion).
struct SelectedInverse {
  int bandwidth = 0;  ///< entries (i, j) of the band block with |i − j| <= bandwidth are held
  Eigen::Index band_size = 0;  ///< m, unknowns of the band block
  /// Z(i, j), i <= j <= i + bandwidth, at [i·(bandwidth + 1) + (j − i)] (0 past the end).
  std::vector<double> band;
  Eigen::MatrixXd cross;   ///< m × k block of M⁻¹ coupling band and border unknowns
  Eigen::MatrixXd border;  ///< k × k block of M⁻¹ of the border unknowns
  /// M⁻¹(i, j) for any i, j of the whole system inside the band or touching the border; throws
  /// std::out_of_range for a band pair farther apart than `bandwidth`.
  double operator()(Eigen::Index i, Eigen::Index j) const;
};

struct TikhonovSolverStats {
  int factorizations = 0;
  int solves = 0;
  double analyze_s = 0;
  double factorize_s = 0;  ///< total over all factorisations
  double solve_s = 0;
  /// AᵀA was formed from A's rows in band storage (every row narrow); else by cholmod_aat.
  bool banded_normal = false;
  /// Rank of the band–border coupling: triangular solves the border costs per λ (<= k).
  int border_rank = 0;
  int selected_inversions = 0;
  double selected_inverse_s = 0;
};

class TikhonovSolver {
 public:
  /// Forms AᵀA and runs the symbolic analysis.  Throws std::runtime_error if CHOLMOD fails.
  ///
  /// `border_columns` = k > 0: the last k columns of A couple to (nearly) all others, as the
  /// zero-adjustment differences Δe of Eq. (7) do, so AᵀA is a band with a k-wide border.
  /// CHOLMOD then factorises only the band B (twice as fast as band plus border: the border rows
  /// of the factor are dense) and the border is eliminated by its k × k Schur complement
  /// S = D − Cᵀ B⁻¹ C (rank(C) forward substitutions per λ, in one pass over the factor).  The
  /// band block alone must be positive definite at the λ used (it is for every gauge of
  /// four_sensor_system: f alone has no null direction there, or λ > 0).
  ///
  /// `penalty` (optional, n × n over all unknowns, symmetric, both triangles stored): the general
  /// form AᵀA + λ²P.  It needs the banded path (every row of A narrow); its band part must lie
  /// within 64 of the diagonal, its border rows and columns may be dense.  Unknowns where P is
  /// zero carry no penalty (a flat prior).  Empty: AᵀA + λ²I (CHOLMOD's shift), border included.
  explicit TikhonovSolver(const Eigen::SparseMatrix<double>& A, int border_columns = 0,
                          const Eigen::SparseMatrix<double>& penalty = {});
  /// The same, taking A over instead of copying it (at N = 10⁶ the copy is 200 MB).
  explicit TikhonovSolver(Eigen::SparseMatrix<double>&& A, int border_columns = 0,
                          const Eigen::SparseMatrix<double>& penalty = {});
  ~TikhonovSolver();
  /// Another solver over the same A and AᵀA (shared, not copied) with its own factor (the
  /// symbolic analysis is copied, not redone), for use on another thread.  Its stats start at 0.
  std::unique_ptr<TikhonovSolver> worker() const;
  TikhonovSolver(const TikhonovSolver&) = delete;
  TikhonovSolver& operator=(const TikhonovSolver&) = delete;

  /// Numeric factorisation of AᵀA + λ²I (or + λ²P).  λ = 0 gives the plain least-squares normal
  /// equations.
  SolverStatus factorize(double lambda);
  /// factorize(λ), then x = solve_normal(rhs), with rhs's forward substitution done in the same
  /// pass over the factor as the border's (one pass fewer per λ; what an L-curve sweep calls).
  SolverStatus factorize_and_solve(double lambda, const Eigen::VectorXd& rhs, Eigen::VectorXd& x);
  /// factorize(λ), then q = vᵀ(AᵀA + λ²P)⁻¹v from the forward substitution alone, done in the
  /// same pass over the factor as the border's (no back substitution): what a likelihood needs
  /// (bᵀb − q is the penalised residual ‖b − Ax‖² + λ²xᵀPx for v = Aᵀb).
  SolverStatus factorize_and_quadratic_form(double lambda, const Eigen::VectorXd& v, double& q);
  /// Solves (AᵀA + λ²I)·y = rhs with the current factor.
  Eigen::VectorXd solve_normal(const Eigen::VectorXd& rhs);
  /// vᵀ(AᵀA + λ²I)⁻¹v with the current factor (one triangular solve for the LDLᵀ factor).
  double inverse_quadratic_form(const Eigen::VectorXd& v);
  /// X_λ for right-hand side b: solve_normal(Aᵀb).
  Eigen::VectorXd solve(const Eigen::VectorXd& b);
  /// P·x (x over all unknowns), or x itself without a penalty: the penalty's part of the normal
  /// equations, so ‖Lx‖² = x·apply_penalty(x).
  Eigen::VectorXd apply_penalty(const Eigen::VectorXd& x) const;
  bool has_penalty() const;
  /// log det(AᵀA + λ²P) of the current factorisation (band pivots and the border's Schur block).
  double log_det() const;
  /// Selected entries of the inverse of the current factorisation (see SelectedInverse).
  /// Computed once per factorisation and kept (valid until the next factorisation): at N = 10⁶
  /// it is 64 MB, so it is not copied out.
  const SelectedInverse& selected_inverse();
  /// tr(M⁻¹·P) from a selected inverse of the current factorisation (P inside the band): what
  /// the effective degrees of freedom n − λ²·tr(M⁻¹P) need.  Without a penalty, tr(M⁻¹).
  double trace_inverse_penalty(const SelectedInverse& z) const;
  /// tr(M⁻¹·AᵀA) from a selected inverse of the current factorisation: the effective degrees of
  /// freedom of the fit (the trace of the hat matrix A·M⁻¹·Aᵀ), summed directly.  Equal to
  /// n − λ²·tr(M⁻¹P) in exact arithmetic, but that difference loses the answer when edf ≪ n: at
  /// n = 10⁶ and edf ≈ 5 the subtrahend needs 7 correct digits, and λ²·P (entries up to 6λ²)
  /// weighs the round-off of the large, smooth entries of M⁻¹ by λ² (a second-difference penalty
  /// takes their fourth differences).  AᵀA's entries are O(1): the same round-off costs λ² less.
  double trace_inverse_normal(const SelectedInverse& z) const;
  const Eigen::SparseMatrix<double>& A() const { return *A_; }
  /// λ of the last factorisation, and whether it succeeded (its factor is the current one).
  double lambda() const { return lambda_; }
  bool factorized() const;
  /// An upper bound of the largest singular value of A (sqrt of ‖AᵀA‖₁), for λ ranges.
  double sigma_max_bound() const { return sigma_max_bound_; }
  const TikhonovSolverStats& stats() const { return stats_; }
  /// After a factorisation that returned not_positive_definite: where it failed.
  const FactorFailure& failure() const { return failure_; }

 private:
  struct Normal;  // AᵀA in CHOLMOD form, shared by workers
  struct Impl;    // CHOLMOD workspace and factor, one per solver
  TikhonovSolver() = default;
  void build(int border_columns, const Eigen::SparseMatrix<double>& penalty);
  bool build_banded(const Eigen::SparseMatrix<double>& At, const Eigen::SparseMatrix<double>& P);
  void compress_border();
  SolverStatus factorize_impl(double lambda, const Eigen::VectorXd* rhs, Eigen::VectorXd* x,
                              double* quad);
  double quadratic_form_from_forward(const Eigen::VectorXd& v,
                                     const Eigen::Ref<const Eigen::VectorXd>& z);
  void finish_solve(const Eigen::VectorXd& rhs, Eigen::VectorXd& z, Eigen::VectorXd& out);
  void build_general(const Eigen::SparseMatrix<double>& At);
  std::shared_ptr<const Eigen::SparseMatrix<double>> A_;
  std::shared_ptr<Normal> normal_;
  std::unique_ptr<Impl> impl_;
  int border_ = 0;
  double lambda_ = -1.0;
  double sigma_max_bound_ = 0.0;
  TikhonovSolverStats stats_;
  FactorFailure failure_;
};

}  // namespace errsep::core

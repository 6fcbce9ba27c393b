#pragma once
// Tikhonov solutions of A·X ≈ b (Eq. 17 of Zhao 2019): X_λ = (AᵀA + λ²I)⁻¹Aᵀb, by CHOLMOD on the
// regularised normal equations.  AᵀA is formed once (from A's rows in band storage when they are
// narrow, else by cholmod_aat; upper triangle kept); the symbolic analysis (natural ordering,
// simplicial LDLᵀ: AᵀA is banded with a few dense trailing rows) is done once in the constructor
// and each λ costs one numeric factorisation with CHOLMOD's diagonal shift β = λ² (Ceres-style:
// Tikhonov is a per-solve option, not a matrix edit).  This is the only place that talks to CHOLMOD
// (its C API, in tikhonov_solver.cpp).
//
// A sweep over λ can run on several threads: worker() gives another solver over the same A and
// AᵀA (shared, read-only) with its own CHOLMOD workspace and a copy of the analysed factor.  Each
// solver object is used by one thread at a time.
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <memory>
#include <string>

namespace errsep::core {

enum class SolverStatus {
  success,
  not_positive_definite,  ///< CHOLMOD reported a zero/negative pivot (rank-deficient A at λ = 0)
  analysis_failed,
  not_factorized,
};
const char* to_string(SolverStatus s);

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
  explicit TikhonovSolver(const Eigen::SparseMatrix<double>& A, int border_columns = 0);
  /// The same, taking A over instead of copying it (at N = 10⁶ the copy is 200 MB).
  explicit TikhonovSolver(Eigen::SparseMatrix<double>&& A, int border_columns = 0);
  ~TikhonovSolver();
  /// Another solver over the same A and AᵀA (shared, not copied) with its own factor (the
  /// symbolic analysis is copied, not redone), for use on another thread.  Its stats start at 0.
  std::unique_ptr<TikhonovSolver> worker() const;
  TikhonovSolver(const TikhonovSolver&) = delete;
  TikhonovSolver& operator=(const TikhonovSolver&) = delete;

  /// Numeric factorisation of AᵀA + λ²I.  λ = 0 gives the plain least-squares normal equations.
  SolverStatus factorize(double lambda);
  /// factorize(λ), then x = solve_normal(rhs), with rhs's forward substitution done in the same
  /// pass over the factor as the border's (one pass fewer per λ; what an L-curve sweep calls).
  SolverStatus factorize_and_solve(double lambda, const Eigen::VectorXd& rhs, Eigen::VectorXd& x);
  /// Solves (AᵀA + λ²I)·y = rhs with the current factor.
  Eigen::VectorXd solve_normal(const Eigen::VectorXd& rhs);
  /// vᵀ(AᵀA + λ²I)⁻¹v with the current factor (one triangular solve for the LDLᵀ factor).
  double inverse_quadratic_form(const Eigen::VectorXd& v);
  /// X_λ for right-hand side b: solve_normal(Aᵀb).
  Eigen::VectorXd solve(const Eigen::VectorXd& b);

  const Eigen::SparseMatrix<double>& A() const { return *A_; }
  double lambda() const { return lambda_; }
  /// An upper bound of the largest singular value of A (sqrt of ‖AᵀA‖₁), for λ ranges.
  double sigma_max_bound() const { return sigma_max_bound_; }
  const TikhonovSolverStats& stats() const { return stats_; }

 private:
  struct Normal;  // AᵀA in CHOLMOD form, shared by workers
  struct Impl;    // CHOLMOD workspace and factor, one per solver
  TikhonovSolver() = default;
  void build(int border_columns);
  bool build_banded(const Eigen::SparseMatrix<double>& At);
  void compress_border();
  SolverStatus factorize_impl(double lambda, const Eigen::VectorXd* rhs, Eigen::VectorXd* x);
  void finish_solve(const Eigen::VectorXd& rhs, Eigen::VectorXd& z, Eigen::VectorXd& out);
  void build_general(const Eigen::SparseMatrix<double>& At);
  std::shared_ptr<const Eigen::SparseMatrix<double>> A_;
  std::shared_ptr<Normal> normal_;
  std::unique_ptr<Impl> impl_;
  int border_ = 0;
  double lambda_ = -1.0;
  double sigma_max_bound_ = 0.0;
  TikhonovSolverStats stats_;
};

}  // namespace errsep::core

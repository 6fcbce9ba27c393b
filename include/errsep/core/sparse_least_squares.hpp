#pragma once
// A generic sparse linear least-squares solve, min ‖A·x − b‖, by a Cholesky factorisation of the
// normal matrix AᵀA with CHOLMOD, and the diagonal of (AᵀA)⁻¹ by selected inversion.
//
// This is errsep's one place for an unregularised sparse least-squares problem (the displacement
// method's joint estimate, core/displacement_joint.hpp).  tikhonov_solver.* is the other CHOLMOD
// user and is specialised for a banded system swept over λ; the two share no code because that
// solver's band storage and rank-compressed border do not fit a general sparsity pattern, and a
// general pattern needs a fill-reducing ordering that a pure band does not.
//
// Covariance.  With independent readings of equal variance σ², Cov(x̂) = σ²·(AᵀA)⁻¹.  Its
// diagonal is computed by the Takahashi recurrences on the factor L·D·Lᵀ = P·AᵀA·Pᵀ:
//   Z = D⁻¹L⁻¹ + (I − Lᵀ)·Z,   so for j = n−1 … 0 and i in the pattern of column j of L:
//   Z_ij = −Σ_k L_kj Z_ik,  Z_jj = 1/D_j − Σ_k L_kj Z_kj   (k over column j's sub-diagonal pattern)
// Every Z_ik needed lies in the pattern of L (the sub-diagonal pattern of a column is a clique of
// the filled graph), so the cost is Σ_j |L_j|² (times a binary search) and the memory one extra
// copy of L, not the dense n × n inverse.
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <memory>
#include <string>

namespace errsep::core {

enum class SparseLeastSquaresStatus {
  success,
  not_positive_definite,  ///< AᵀA singular: A has dependent columns (an unfixed gauge)
  cholmod_failed,         ///< analysis or factorisation failed (out of memory, ...)
};

const char* to_string(SparseLeastSquaresStatus s);

struct SparseLeastSquaresOptions {
  /// Fill-reducing ordering: AMD on AᵀA (general), or natural when the caller has ordered the
  /// unknowns so that the factor has no fill (e.g. per-point unknowns before shared ones).
  bool natural_ordering = false;
};

struct SparseLeastSquaresStats {
  Eigen::Index unknowns = 0, observations = 0;
  std::size_t factor_nonzeros = 0;
  double analyse_s = 0, factorise_s = 0;
};

/// Factorises AᵀA once in the constructor; solves and the inverse's diagonal reuse the factor.
/// Not copyable (owns the CHOLMOD workspace).  Not thread-safe.
class SparseLeastSquares {
 public:
  /// `a_transposed` is Aᵀ (n unknowns × m observations, one column per observation: CHOLMOD
  /// factors F·Fᵀ of an unsymmetric F, and taking Aᵀ saves transposing a large A).  The solver
  /// keeps a reference to it: it must outlive the solver.  Throws std::invalid_argument if it is
  /// empty or not compressed; a failed factorisation is reported by status(), not thrown.
  explicit SparseLeastSquares(const Eigen::SparseMatrix<double>& a_transposed,
                              const SparseLeastSquaresOptions& opts = {});
  ~SparseLeastSquares();
  SparseLeastSquares(const SparseLeastSquares&) = delete;
  SparseLeastSquares& operator=(const SparseLeastSquares&) = delete;

  SparseLeastSquaresStatus status() const { return status_; }
  /// What failed and where (empty on success).
  const std::string& message() const { return message_; }
  const SparseLeastSquaresStats& stats() const { return stats_; }

  /// x̂ = argmin ‖A·x − b‖ (b has one entry per observation).  Throws std::logic_error unless
  /// status() is success, std::invalid_argument on a size mismatch.
  Eigen::VectorXd solve(const Eigen::VectorXd& b) const;
  /// (AᵀA)⁻¹·rhs for n × k right-hand sides (e.g. linear functionals of x̂ for their variance).
  Eigen::MatrixXd solve_normal(const Eigen::MatrixXd& rhs) const;
  /// diag((AᵀA)⁻¹), by the Takahashi recurrences above.
  Eigen::VectorXd inverse_diagonal() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  const Eigen::SparseMatrix<double>& at_;
  SparseLeastSquaresStatus status_ = SparseLeastSquaresStatus::cholmod_failed;
  std::string message_;
  SparseLeastSquaresStats stats_;
  void require_success() const;
};

}  // namespace errsep::core

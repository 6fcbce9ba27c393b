#pragma once
// LDLᵀ of a symmetric positive definite band matrix of small half-bandwidth b (the four-sensor
// normal matrix: b = s2 + s3 + s4, 7 for the paper's spacings), by the up-looking row recurrence
// with the rows of L kept contiguous.  Private to src/core (tikhonov_solver.cpp).
//
// Why not CHOLMOD's simplicial LDLᵀ: for such a thin band its per-entry bookkeeping (row
// patterns from the elimination tree, scatter and gather) costs several times the b²/2
// multiply-adds a row needs; at N = 10⁶ it was 30 % of the default estimator's time (issue 15).
// LAPACK's dpbtrf calls the BLAS twice per column on vectors of length b, whose per-call cost
// dominates at this width.  Here a row is b²/2 + b multiply-adds in registers and cache, and the
// forward substitution of a few right-hand sides (the border's and the criterion's) rides along
// in the same pass, so a λ reads the matrix once.
#include <Eigen/Core>
#include <vector>

namespace errsep::core::detail {

class BandLdlt {
 public:
  /// Factorises M = A + pen_scale·P + shift·I, m × m, half-bandwidth b: A and P (P may be null)
  /// in upper band storage, entry (i, j), i <= j <= i + b, at [j·(b + 1) + (j − i)] (the entries
  /// with i < 0 are zeros).  With `cols` > 0 also z = L⁻¹·rhs for rhs column-major m × cols
  /// (rhs and z may not overlap).  Returns −1, or the first pivot D_j that is not positive and
  /// finite; the factorisation stops there (the factor is then unusable; d() holds D_j).
  Eigen::Index factorize(const double* a, const double* p, double pen_scale, double shift,
                         Eigen::Index m, int b, const double* rhs, Eigen::Index cols, double* z);
  /// z = L⁻¹·v, v and z column-major m × cols (may be the same array).
  void forward(const double* v, Eigen::Index cols, double* z) const;
  /// x = L⁻ᵀ·D⁻¹·y (CHOLMOD's DLt system), column-major m × cols (may be the same array).
  void back_dlt(const double* y, Eigen::Index cols, double* x) const;
  /// L(i, j) for j < i <= j + b (unit lower triangular: the diagonal is 1 and not stored).
  double l(Eigen::Index i, Eigen::Index j) const {
    return l_[static_cast<std::size_t>(i) * static_cast<std::size_t>(b_) +
              static_cast<std::size_t>(j - i + b_)];
  }
  const Eigen::VectorXd& d() const { return d_; }
  int bandwidth() const { return b_; }
  Eigen::Index size() const { return m_; }

 private:
  Eigen::Index m_ = 0;
  int b_ = 0;
  /// Row i of L: L(i, k) for k = i − b … i − 1 at [i·b + (k − i + b)] (zeros for k < 0).
  std::vector<double> l_;
  Eigen::VectorXd d_;
};

}  // namespace errsep::core::detail

// CHOLMOD is used directly here rather than through Eigen's CholmodSupport: selected inversion
// needs the factor's pattern and D, which Eigen's wrapper does not expose.  This file and
// tikhonov_solver.cpp (with their private cholmod_views.hpp) are the only ones that include
// <cholmod.h> (see the header for why two).
#include "errsep/core/sparse_least_squares.hpp"

#include <cholmod.h>

#include <algorithm>
#include <chrono>
#include <numeric>
#include <stdexcept>
#include <vector>

#include "cholmod_views.hpp"

namespace errsep::core {
namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

const char* to_string(SparseLeastSquaresStatus s) {
  switch (s) {
    case SparseLeastSquaresStatus::success:
      return "success";
    case SparseLeastSquaresStatus::not_positive_definite:
      return "normal matrix not positive definite (dependent unknowns: a gauge not fixed?)";
    case SparseLeastSquaresStatus::cholmod_failed:
      return "CHOLMOD failed";
  }
  return "?";
}

struct SparseLeastSquares::Impl {
  cholmod_common cm{};
  cholmod_factor* L = nullptr;
  cholmod_sparse F{};  // view of Aᵀ
  Impl() { cholmod_start(&cm); }
  ~Impl() {
    if (L) cholmod_free_factor(&L, &cm);
    cholmod_finish(&cm);
  }
};

SparseLeastSquares::SparseLeastSquares(const Eigen::SparseMatrix<double>& at,
                                       const SparseLeastSquaresOptions& opts)
    : impl_(std::make_unique<Impl>()), at_(at) {
  if (at.rows() == 0 || at.cols() == 0 || !at.isCompressed())
    throw std::invalid_argument(
        "sparse least squares: Aᵀ must be a non-empty compressed column matrix");
  stats_.unknowns = at.rows();
  stats_.observations = at.cols();
  auto& cm = impl_->cm;
  cm.nmethods = 1;
  cm.method[0].ordering = opts.natural_ordering ? CHOLMOD_NATURAL : CHOLMOD_AMD;
  cm.postorder = opts.natural_ordering ? 0 : 1;
  cm.supernodal = CHOLMOD_SIMPLICIAL;  // LDLᵀ: selected inversion reads D and L column by column
  cm.final_ll = 0;
  cm.print = 0;
  cm.error_handler = nullptr;   // status checked after every call
  impl_->F = detail::view(at);  // unsymmetric: CHOLMOD factors F·Fᵀ = AᵀA
  auto& F = impl_->F;

  auto t0 = std::chrono::steady_clock::now();
  impl_->L = cholmod_analyze(&F, &cm);
  stats_.analyse_s = seconds_since(t0);
  if (!impl_->L || cm.status < CHOLMOD_OK) {
    message_ = "CHOLMOD analysis failed (status " + std::to_string(cm.status) + ")";
    return;
  }
  t0 = std::chrono::steady_clock::now();
  const int ok = cholmod_factorize(&F, impl_->L, &cm);
  stats_.factorise_s = seconds_since(t0);
  // cholmod_factorize returns TRUE on a non-positive-definite matrix: check status and minor.
  if (cm.status == CHOLMOD_NOT_POSDEF || impl_->L->minor < impl_->L->n) {
    status_ = SparseLeastSquaresStatus::not_positive_definite;
    message_ = "normal matrix not positive definite at column " + std::to_string(impl_->L->minor) +
               " of the permuted order";
    return;
  }
  if (!ok || cm.status < CHOLMOD_OK) {
    message_ = "CHOLMOD factorisation failed (status " + std::to_string(cm.status) + ")";
    return;
  }
  const auto* nz = static_cast<const int*>(impl_->L->nz);
  for (size_t j = 0; j < impl_->L->n; ++j)
    stats_.factor_nonzeros += static_cast<std::size_t>(nz[j]);
  status_ = SparseLeastSquaresStatus::success;
}

SparseLeastSquares::~SparseLeastSquares() = default;

void SparseLeastSquares::require_success() const {
  if (status_ != SparseLeastSquaresStatus::success)
    throw std::logic_error(std::string("sparse least squares: no factor (") + to_string(status_) +
                           (message_.empty() ? "" : ": " + message_) + ")");
}

Eigen::MatrixXd SparseLeastSquares::solve_normal(const Eigen::MatrixXd& rhs) const {
  require_success();
  if (rhs.rows() != stats_.unknowns)
    throw std::invalid_argument("sparse least squares: right-hand side has " +
                                std::to_string(rhs.rows()) + " rows, expected " +
                                std::to_string(stats_.unknowns));
  auto& cm = impl_->cm;
  cholmod_dense b = detail::view(rhs.data(), rhs.rows(), rhs.cols());
  cholmod_dense* x = cholmod_solve(CHOLMOD_A, impl_->L, &b, &cm);
  if (!x || cm.status < CHOLMOD_OK) {
    if (x) cholmod_free_dense(&x, &cm);
    throw std::runtime_error("sparse least squares: CHOLMOD solve failed (status " +
                             std::to_string(cm.status) + ")");
  }
  Eigen::MatrixXd out =
      Eigen::Map<const Eigen::MatrixXd>(static_cast<const double*>(x->x), rhs.rows(), rhs.cols());
  cholmod_free_dense(&x, &cm);
  return out;
}

Eigen::VectorXd SparseLeastSquares::solve(const Eigen::VectorXd& b) const {
  require_success();
  if (b.size() != stats_.observations)
    throw std::invalid_argument("sparse least squares: " + std::to_string(b.size()) +
                                " observations given, the matrix has " +
                                std::to_string(stats_.observations));
  const Eigen::VectorXd atb = at_ * b;
  return solve_normal(atb);
}

Eigen::VectorXd SparseLeastSquares::inverse_diagonal() const {
  require_success();
  const cholmod_factor& L = *impl_->L;
  const auto n = static_cast<Eigen::Index>(L.n);
  const auto* lp = static_cast<const int*>(L.p);
  const auto* li = static_cast<const int*>(L.i);
  const auto* lx = static_cast<const double*>(L.x);
  const auto* lnz = static_cast<const int*>(L.nz);
  const auto* perm = static_cast<const int*>(L.Perm);

  // Sub-diagonal pattern of L in compressed columns, rows sorted (for the binary search of Z_ik).
  std::vector<std::size_t> cp(static_cast<std::size_t>(n) + 1, 0);
  for (Eigen::Index j = 0; j < n; ++j)
    cp[static_cast<std::size_t>(j) + 1] =
        cp[static_cast<std::size_t>(j)] + static_cast<std::size_t>(lnz[j] - 1);  // diag is first
  std::vector<int> rows(cp.back());
  std::vector<double> lval(cp.back()), zval(cp.back());
  Eigen::VectorXd d(n);
  std::vector<std::pair<int, double>> col;
  for (Eigen::Index j = 0; j < n; ++j) {
    const int start = lp[j];
    d(j) = lx[start];  // LDLᵀ: the diagonal entry of column j holds D_j
    col.clear();
    for (int q = start + 1; q < start + lnz[j]; ++q)
      col.emplace_back(li[q], lx[q]);
    std::sort(col.begin(), col.end());
    std::size_t o = cp[static_cast<std::size_t>(j)];
    for (const auto& [r, v] : col) {
      rows[o] = r;
      lval[o++] = v;
    }
  }
  Eigen::VectorXd zdiag(n);
  // Z(r, c) for r > c, both in the filled pattern.
  auto z_at = [&](int r, int c) -> double {
    if (r == c) return zdiag(r);
    if (r < c) std::swap(r, c);
    const auto b = rows.begin() + static_cast<std::ptrdiff_t>(cp[static_cast<std::size_t>(c)]);
    const auto e = rows.begin() + static_cast<std::ptrdiff_t>(cp[static_cast<std::size_t>(c) + 1]);
    const auto it = std::lower_bound(b, e, r);
    if (it == e || *it != r)
      throw std::logic_error("sparse least squares: selected inversion left the factor's pattern");
    return zval[static_cast<std::size_t>(it - rows.begin())];
  };
  for (Eigen::Index j = n - 1; j >= 0; --j) {
    const std::size_t b = cp[static_cast<std::size_t>(j)], e = cp[static_cast<std::size_t>(j) + 1];
    for (std::size_t a = b; a < e; ++a) {
      double s = 0;
      for (std::size_t k = b; k < e; ++k)
        s += lval[k] * z_at(rows[a], rows[k]);
      zval[a] = -s;
    }
    double s = 0;
    for (std::size_t a = b; a < e; ++a)
      s += lval[a] * zval[a];
    zdiag(j) = 1.0 / d(j) - s;
  }
  Eigen::VectorXd out(n);
  for (Eigen::Index k = 0; k < n; ++k)
    out(perm ? perm[k] : k) = zdiag(k);
  return out;
}

}  // namespace errsep::core

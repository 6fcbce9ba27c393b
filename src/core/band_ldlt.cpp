#include "band_ldlt.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <string>

namespace errsep::core::detail {
namespace {
constexpr int kMaxBandwidth = 64;  // TikhonovSolver's banded path takes bands up to 64 wide
}

Eigen::Index BandLdlt::factorize(const double* a, const double* p, double pen_scale, double shift,
                                 Eigen::Index m, int b, const double* rhs, Eigen::Index cols,
                                 double* z) {
  if (b < 0 || b > kMaxBandwidth)
    throw std::invalid_argument("BandLdlt: half-bandwidth " + std::to_string(b) + " outside 0.." +
                                std::to_string(kMaxBandwidth));
  m_ = m;
  b_ = b;
  const auto bs = static_cast<std::size_t>(b);
  const auto w = bs + 1;
  l_.resize(static_cast<std::size_t>(m) * bs);  // kept between λ: no page faults per factorisation
  d_.resize(m);
  std::array<double, kMaxBandwidth> u{};  // u_k = L(j, k)·D_k of the row being formed
  for (Eigen::Index j = 0; j < m; ++j) {
    const Eigen::Index lo = std::max<Eigen::Index>(0, j - b);
    const auto ju = static_cast<std::size_t>(j);
    const double* aj = a + ju * w;  // aj[j − k] = A(k, j)
    const double* pj = p != nullptr ? p + ju * w : nullptr;
    double* lj = l_.data() + ju * bs;  // lj[k − j + b] = L(j, k)
    // Row j of L·D solves L(0:j, 0:j)·u = M(0:j, j) (the up-looking recurrence): u_k = M(k, j) −
    // Σ_{lo <= q < k} L(k, q)·u_q.  Rows of L before lo do not reach column j.
    for (Eigen::Index k = lo; k < j; ++k) {
      const auto off = static_cast<std::size_t>(j - k);
      double s = aj[off] + (pj != nullptr ? pen_scale * pj[off] : 0.0);
      const double* lk = l_.data() + static_cast<std::size_t>(k) * bs;  // lk[q − k + b] = L(k, q)
      for (Eigen::Index q = lo; q < k; ++q)
        s -= lk[q - k + b] * u[static_cast<std::size_t>(q - lo)];
      u[static_cast<std::size_t>(k - lo)] = s;
    }
    double dj = aj[0] + shift + (pj != nullptr ? pen_scale * pj[0] : 0.0);
    for (Eigen::Index k = j - b; k < lo; ++k)
      lj[k - j + b] = 0.0;  // the first rows: no columns before 0
    for (Eigen::Index k = lo; k < j; ++k) {
      const double uk = u[static_cast<std::size_t>(k - lo)];
      const double l = uk / d_(k);
      lj[k - j + b] = l;
      dj -= l * uk;
    }
    d_(j) = dj;
    if (!(dj > 0.0 && std::isfinite(dj))) return j;
    for (Eigen::Index c = 0; c < cols; ++c) {
      const double* rc = rhs + c * m;
      double* zc = z + c * m;
      double s = rc[j];
      for (Eigen::Index k = lo; k < j; ++k)
        s -= lj[k - j + b] * zc[k];
      zc[j] = s;
    }
  }
  return -1;
}

void BandLdlt::forward(const double* v, Eigen::Index cols, double* z) const {
  const auto bs = static_cast<std::size_t>(b_);
  for (Eigen::Index c = 0; c < cols; ++c) {
    const double* vc = v + c * m_;
    double* zc = z + c * m_;
    for (Eigen::Index j = 0; j < m_; ++j) {
      const Eigen::Index lo = std::max<Eigen::Index>(0, j - b_);
      const double* lj = l_.data() + static_cast<std::size_t>(j) * bs;
      double s = vc[j];
      for (Eigen::Index k = lo; k < j; ++k)
        s -= lj[k - j + b_] * zc[k];
      zc[j] = s;
    }
  }
}

void BandLdlt::back_dlt(const double* y, Eigen::Index cols, double* x) const {
  const auto bs = static_cast<std::size_t>(b_);
  for (Eigen::Index c = 0; c < cols; ++c) {
    const double* yc = y + c * m_;
    double* xc = x + c * m_;
    for (Eigen::Index j = 0; j < m_; ++j)
      xc[j] = yc[j] / d_(j);
    // Lᵀx = t by rows of L from the last: x_i is final once the rows below it are done, and row
    // i then takes L(i, k)·x_i off every t_k it reaches.
    for (Eigen::Index i = m_ - 1; i > 0; --i) {
      const Eigen::Index lo = std::max<Eigen::Index>(0, i - b_);
      const double* li = l_.data() + static_cast<std::size_t>(i) * bs;
      const double xi = xc[i];
      for (Eigen::Index k = lo; k < i; ++k)
        xc[k] -= li[k - i + b_] * xi;
    }
  }
}

}  // namespace errsep::core::detail

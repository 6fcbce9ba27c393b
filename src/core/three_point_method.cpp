#include "errsep/core/three_point_method.hpp"

#include <Eigen/Dense>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace errsep::core {

bool ThreePointOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& msg) {
    if (why) *why = msg;
    return false;
  };
  if (s1 < 1) return fail("s1 = " + std::to_string(s1) + ": must be >= 1");
  if (s2 < 1) return fail("s2 = " + std::to_string(s2) + ": must be >= 1");
  if (!(std::isfinite(sample_interval_mm) && sample_interval_mm > 0))
    return fail("sample_interval_mm = " + std::to_string(sample_interval_mm) +
                ": must be finite and > 0");
  return true;
}

ThreePointResult separate_three_point(const Eigen::MatrixXd& m_um, const ThreePointOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("three-point method: " + why);
  if (m_um.cols() != 3)
    throw std::invalid_argument("three-point method: readings have " + std::to_string(m_um.cols()) +
                                " columns, need 3 (sensors 0, 1, 2)");
  const Eigen::Index P = m_um.rows();
  if (P < 1) throw std::invalid_argument("three-point method: no slide positions");
  if (!m_um.allFinite()) throw std::invalid_argument("three-point method: non-finite reading");
  const int s1 = opts.s1, s2 = opts.s2;
  const Eigen::Index N = P + s1 + s2;
  const double c1 = -static_cast<double>(s1 + s2) / s2, c2 = static_cast<double>(s1) / s2;

  // g(x_n) (Zhao Eq. 9 with the first row of C, Eq. 3).
  const Eigen::VectorXd g = m_um.col(0) + c1 * m_um.col(1) + c2 * m_um.col(2);
  // Unknowns f_1 .. f_{N-2}; f_0 = f_{N-1} = 0 (Zhao Eq. 11) drop out of the equations.
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(P, N - 2);
  auto put = [&](Eigen::Index row, Eigen::Index k, double c) {
    if (k >= 1 && k <= N - 2) a(row, k - 1) += c;
  };
  for (Eigen::Index n = 0; n < P; ++n) {
    put(n, n, 1.0);
    put(n, n + s1, c1);
    put(n, n + s1 + s2, c2);
  }
  ThreePointResult res;
  res.f_um = Eigen::VectorXd::Zero(N);
  if (N > 2) {
    Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(a);
    res.f_um.segment(1, N - 2) = cod.solve(g);
    res.null_modes = (N - 2) - cod.rank();
    res.residual_rms_um =
        P ? (a * res.f_um.segment(1, N - 2) - g).norm() / std::sqrt(double(P)) : 0;
  }
  // Back to the slide: S = m_0 - f(x_n), γ = (m_1 - f(x_n + O_1) - S) / O_1.
  const double o1_um = 1000.0 * s1 * opts.sample_interval_mm;  // mm -> µm per rad
  res.S_um = m_um.col(0) - res.f_um.head(P);
  res.gamma_rad = (m_um.col(1) - res.f_um.segment(s1, P) - res.S_um) / o1_um;
  return res;
}

std::string ThreePointResult::brief_report() const {
  std::ostringstream s;
  s << "three-point method: " << f_um.size() << " surface samples, " << S_um.size()
    << " slide positions, residual rms " << residual_rms_um << " um";
  if (null_modes > 0) s << ", " << null_modes << " homogeneous mode(s) set by minimum norm";
  return s.str();
}

}  // namespace errsep::core

#pragma once
// Generalised three-point (three-sensor) method, the baseline of the four-sensor method in
// Zhao et al. 2019 (their Eqs. 2-3, 11-12, first row of C).  Three sensors at offsets
// O_0 = 0, O_1 = s1·Δx, O_2 = (s1 + s2)·Δx on a carriage read, at slide positions x_n,
//
//   m_j(x_n) = f(x_n + O_j) + S(x_n) + O_j·γ(x_n)          (Zhao Eq. 1, no zero-adjustment)
//
// with f the surface profile, S the straightness and γ the tilt (yaw/pitch) of the slide.  The
// second difference with two sensor spacings
//
//   g(x_n) = m_0 - (s1+s2)/s2 · m_1 + s1/s2 · m_2
//          = f(x_n) - (s1+s2)/s2 · f(x_n + s1Δx) + s1/s2 · f(x_n + (s1+s2)Δx)
//
// eliminates S and γ.  f on N = P + s1 + s2 samples follows from the P equations g(x_n) by least
// squares with the straight-line datum f(x_0) = f(x_{N-1}) = 0 (Zhao Eq. 11).  For s1 + s2 > 2
// the system keeps s1 + s2 - 2 homogeneous modes (roots of the characteristic polynomial other
// than the double root 1); they are resolved by the minimum-norm solution and counted in
// ThreePointResult::null_modes.  A sensor zero-adjustment error Δe is not modelled: it adds a
// parabola to f (Zhao section 2).  The one-axis displacement method is the sequential two-point
// method's cousin; this module lets the methods be compared on the same simulated slideway.
#include <Eigen/Core>
#include <string>

namespace errsep::core {

struct ThreePointOptions {
  int s1 = 1;                       ///< spacing sensor 0 -> 1 in sampling intervals
  int s2 = 1;                       ///< spacing sensor 1 -> 2 in sampling intervals
  double sample_interval_mm = 5.0;  ///< Δx
  bool is_valid(std::string* why = nullptr) const;
};

struct ThreePointResult {
  Eigen::VectorXd f_um;         ///< surface profile at x_0 .. x_{N-1}, datum f_0 = f_{N-1} = 0
  Eigen::VectorXd S_um;         ///< straightness at the P slide positions (relative to f's datum)
  Eigen::VectorXd gamma_rad;    ///< tilt at the P slide positions
  Eigen::Index null_modes = 0;  ///< homogeneous modes left to the minimum-norm choice
  double residual_rms_um = 0;   ///< rms of the second-difference equations' residual
  std::string brief_report() const;
};

/// m_um is P × 3 (columns = sensors 0, 1, 2; rows = slide positions x_n = x_0 + nΔx).  Throws
/// std::invalid_argument on invalid options, a matrix that is not P × 3, P < 1, or non-finite
/// readings.
ThreePointResult separate_three_point(const Eigen::MatrixXd& m_um, const ThreePointOptions& opts);

}  // namespace errsep::core

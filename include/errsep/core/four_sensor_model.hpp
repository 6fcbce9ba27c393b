#pragma once
// The measurement model of the four-sensor method, Eq. (1) of Zhao et al. 2019:
//
//   m_i(x_n) = f(x_n + O_i) + S(x_n) + O_i·γ(x_n) + e_i,   O_i = 0, D2, D2+D3, D2+D3+D4
//
// with f the reference surface profile (µm), S the straightness error of the slideway (µm), γ its
// tilt error (rad here; the paper prints degrees), e_i the zero-adjustment value of configuration
// i relative to configuration 1 (µm, e_1 = 0).  O_i·γ is mm·rad = 1000 µm·rad.
#include <array>
#include <functional>

namespace errsep::core {

/// A function of position along the slide, x in mm.
using ProfileFn = std::function<double(double x_mm)>;

/// The truth a simulation (or the device simulator) plays.
struct SlidewayTruth {
  ProfileFn f_um;                          ///< reference surface profile f(x)
  ProfileFn S_um;                          ///< straightness error S(x)
  ProfileFn gamma_rad;                     ///< tilt error γ(x)
  std::array<double, 4> e_um{0, 0, 0, 0};  ///< zero-adjustment values e_1..e_4 (e_1 = 0)
};

/// Eq. (1) for one configuration: the reading of a sensor offset by `offset_mm` from
/// configuration 1 when the slide is at `x_mm`, without noise or zero-adjustment.
inline double four_sensor_reading_um(const SlidewayTruth& t, double x_mm, double offset_mm) {
  return t.f_um(x_mm + offset_mm) + t.S_um(x_mm) + 1000.0 * offset_mm * t.gamma_rad(x_mm);
}

constexpr double kDegPerRad = 57.29577951308232;
constexpr double kRadPerDeg = 1.0 / kDegPerRad;

}  // namespace errsep::core

#pragma once
// Geometry of the four-sensor method (Zhao et al. 2019, section 2): a single displacement sensor
// moved on a sensor stage to four configurations, spaced D_i = s_i * dx from the previous one, and
// a slide sampled every dx.  General integer spacings are supported, not only s2 = s3 = 1.
#include <array>
#include <string>

namespace errsep::core {

struct FourSensorConfig {
  double dx_mm = 5.0;  ///< lateral resolution Δx (sampling interval of the slide), mm
  int s2 = 1;          ///< D2 = s2·Δx, spacing of configuration 2 from 1
  int s3 = 1;          ///< D3 = s3·Δx, spacing of configuration 3 from 2
  int s4 = 5;          ///< D4 = s4·Δx, spacing of configuration 4 from 3
  int N = 69;          ///< number of sampled points of the reference surface f(x_0..x_{N-1})

  /// Number of slide positions P = N − s2 − s3 − s4 (n = 0 … p with p = P − 1, Eq. 5).
  int positions() const { return N - s2 - s3 - s4; }
  /// Offset of configuration i (0-based, i = 0..3) from configuration 1, in samples: 0, s2, s2+s3,
  /// s2+s3+s4.
  std::array<int, 4> offsets_samples() const { return {0, s2, s2 + s3, s2 + s3 + s4}; }
  /// The same offsets in mm: 0, D2, D2+D3, D2+D3+D4.
  std::array<double, 4> offsets_mm() const;
  /// Slide travel L = (P − 1)·Δx and reference length L0 = (N − 1)·Δx, mm.
  double travel_mm() const { return (positions() - 1) * dx_mm; }
  double reference_length_mm() const { return (N - 1) * dx_mm; }

  /// True when usable; otherwise `why` (if given) names the field, its value and the constraint.
  bool is_valid(std::string* why = nullptr) const;
};

}  // namespace errsep::core

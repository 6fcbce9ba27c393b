#include "errsep/core/four_sensor_config.hpp"

#include <cmath>
#include <numeric>

namespace errsep::core {

std::array<double, 4> FourSensorConfig::offsets_mm() const {
  const auto k = offsets_samples();
  return {k[0] * dx_mm, k[1] * dx_mm, k[2] * dx_mm, k[3] * dx_mm};
}

bool FourSensorConfig::is_valid(std::string* why) const {
  auto fail = [&](const std::string& msg) {
    if (why) *why = msg;
    return false;
  };
  if (!(std::isfinite(dx_mm) && dx_mm > 0))
    return fail("dx_mm = " + std::to_string(dx_mm) + ": must be a positive finite length");
  if (s2 < 1) return fail("s2 = " + std::to_string(s2) + ": spacings must be integers >= 1");
  if (s3 < 1) return fail("s3 = " + std::to_string(s3) + ": spacings must be integers >= 1");
  if (s4 < 1) return fail("s4 = " + std::to_string(s4) + ": spacings must be integers >= 1");
  // The profile has N unknowns (plus 4 zero-adjustment terms) but only 2 independent equations per
  // slide position (C has rank 2) and 3 polynomial components are fixed by the constraints, so
  // 2·P + 3 >= N + 4, i.e. N >= 2(s2+s3+s4) + 1; ask for a few more so that the noise level can be
  // estimated from the redundancy (at least 4 redundant equations).
  // A common divisor g > 1 of the spacings leaves every sensor blind to the harmonics of period
  // g samples (e^{iωk_j} = 1 for all offsets k_j), so A would be rank-deficient beyond the three
  // polynomial directions: refuse it.
  if (const int g = std::gcd(std::gcd(s2, s3), s4); g > 1)
    return fail("spacings (" + std::to_string(s2) + ", " + std::to_string(s3) + ", " +
                std::to_string(s4) + ") share the factor " + std::to_string(g) +
                ": profile components with a period of " + std::to_string(g) +
                " samples would be invisible (A rank-deficient); use coprime spacings");
  const int span = s2 + s3 + s4;
  const int min_n = 2 * span + 5;
  if (N < min_n)
    return fail("N = " + std::to_string(N) + ": too few points for spacings (" +
                std::to_string(s2) + ", " + std::to_string(s3) + ", " + std::to_string(s4) +
                "); need N >= 2(s2+s3+s4)+5 = " + std::to_string(min_n));
  return true;
}

}  // namespace errsep::core

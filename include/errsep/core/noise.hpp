#pragma once
// Seeded random draws shared by errsep's simulations (displacement, three-point).  One
// std::mt19937_64 per simulation run: the same seed gives the same numbers on every platform that
// implements the standard engine (the distributions are written out here rather than taken from
// <random>, whose std::normal_distribution output is implementation-defined).
#include <cmath>
#include <cstdint>
#include <random>

namespace errsep::core {

class NoiseSource {
 public:
  explicit NoiseSource(std::uint64_t seed) : rng_(seed) {}

  /// Uniform in [0, 1), 53 random bits.
  double uniform01() { return static_cast<double>(rng_() >> 11) * 0x1.0p-53; }

  /// Uniform in [-half_width, +half_width].
  double uniform(double half_width) { return half_width * (2.0 * uniform01() - 1.0); }

  /// Normal with mean 0 and standard deviation sigma (Box-Muller, one value per call; sigma = 0
  /// returns 0 without consuming the engine, so switching a noise source off does not shift the
  /// others' streams).
  double normal(double sigma) {
    if (sigma == 0.0) return 0.0;
    if (have_spare_) {
      have_spare_ = false;
      return sigma * spare_;
    }
    double u1 = uniform01();
    while (u1 <= 0.0)
      u1 = uniform01();
    const double u2 = uniform01();
    const double radius = std::sqrt(-2.0 * std::log(u1));
    constexpr double kTwoPi = 6.283185307179586;
    spare_ = radius * std::sin(kTwoPi * u2);
    have_spare_ = true;
    return sigma * radius * std::cos(kTwoPi * u2);
  }

  std::mt19937_64& engine() { return rng_; }

 private:
  std::mt19937_64 rng_;
  double spare_ = 0.0;
  bool have_spare_ = false;
};

}  // namespace errsep::core

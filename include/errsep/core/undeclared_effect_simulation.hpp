#pragma once
// Simulated four-sensor scans with one effect the model does not declare (issue 16): the cases a
// refinement must be tested on, generated rather than designed.  Each case draws random smooth
// profiles (random_smooth_truth: several harmonics of S, γ and f with random periods,
// amplitudes and phases per seed), independent noise σ on every sensor reading (the paper's
// model), and one undeclared effect whose parameters (which configuration, size, sign, period,
// time constant, place) are drawn from the seed too.  The same seed without the effect gives the
// clean scan with the same truth and noise, so the error the effect causes can be told from the
// separation's own.
//
// The sizes are of the order of what a real set-up shows and, at σ = 0.2 µm, at least double the
// clean error of S (checked by tests/core/refine_undeclared.cpp and printed by
// errsep-refine-sweep):
//   pe1          two of the three spacings off by 0.4–0.9 mm (Zhao 2019 section 3's PE1, larger)
//   gain         one configuration (2, 3 or 4) reading 3–6 % high or low
//   drift        linear in time, 0.01–0.03 µm/s: one configuration, or all four at their own rates
//   pe2          slide positioning error, Legendre P1..P3 of 0.3–0.8 mm each (Eq. 20's kind)
//   periodic     lead-screw-like positioning error, 0.3–0.7 mm, period 15–40 mm
//   thermal      first-order warm-up, 2–5 µm, τ 20–80 s: one configuration, or all four
//   traverse     S not repeating on one traverse: P2 and P3 of 1–2 µm each
//   nonlinearity (not in the library) the sensor reads r + κ·(r − r̄)², 2–4 % of the readings'
//                range at its ends (r̄ the mid-range reading)
//   bump         (not in the library) dust or a knock on one traverse: a Gaussian 1.5–3 µm high,
//                5–15 mm wide, somewhere on the travel
#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include "errsep/core/four_sensor_config.hpp"
#include "errsep/core/four_sensor_simulation.hpp"

namespace errsep::core {

enum class UndeclaredEffect {
  none,
  pe1,
  gain,
  drift_one,
  drift_all,
  pe2,
  periodic,
  thermal_one,
  thermal_all,
  traverse,
  nonlinearity,
  bump,
  hysteresis,  ///< the sensor lags by h against the direction its reading changes
};
const char* to_string(UndeclaredEffect e);
std::optional<UndeclaredEffect> undeclared_effect_from_string(std::string_view s);
/// Every kind, none first.
std::vector<UndeclaredEffect> all_undeclared_effects();
/// The name of the library effect (model_effect.hpp) that describes it; empty for none and for
/// the effects the single-scan library lacks (nonlinearity, bump, hysteresis).
std::string library_effect_name(UndeclaredEffect e);
/// Whether the refine that runs on `plan_is_single` (one scan: refine_four_sensor; else the
/// sequence refine) has a model of the effect: the single-scan library's effects on one scan;
/// on a scan sequence those the sequence refine fits (drift, thermal drift, a non-repeating
/// traverse, the hysteresis; its non-linearity test is a finding, not a library effect).
bool in_refine_library(UndeclaredEffect e, bool plan_is_single);

struct UndeclaredCaseOptions {
  FourSensorConfig cfg;  ///< Zhao 2019 Example 1 geometry by default (N = 69, s = 1, 1, 5)
  double sigma_um = 0.1;
  std::uint64_t seed = 1;
  double speed_mm_per_s = 10.0;  ///< scan-order reading times (scan_order_times_s)
  double size = 1.0;             ///< scales the effect's drawn size
  /// The random profiles.  By default a wavy reference (f: 2–5 µm per harmonic, 3–12 periods
  /// over its length, as Zhao 2019 Example 2's Eq. 24), which is what makes the positioning
  /// effects (PE1, PE2, periodic: seen through the slope of f) both matter and show.
  RandomTruthOptions truth = wavy_reference();
  static RandomTruthOptions wavy_reference();
  bool is_valid(std::string* why = nullptr) const;
};

/// The draws of an undeclared effect (its size, sign, place, time constant) for one seed, from a
/// stream of their own, so that the truth and the noise of a seed are the same whatever the
/// effect.  simulate_undeclared and the scan-sequence generator (refine_sweep.cpp) both draw from
/// it, so one seed means the same draws in both.
class UndeclaredEffectDraws {
 public:
  explicit UndeclaredEffectDraws(std::uint64_t seed)
      : rng_(seed * 0x9E3779B97F4A7C15ULL + 0x5bd1e995ULL) {}
  double uni(double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng_); }
  double sign() { return uni(0.0, 1.0) < 0.5 ? -1.0 : 1.0; }
  int pick(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng_); }

 private:
  std::mt19937_64 rng_;
};

/// A hysteresis's h (um) for one seed, on one scan and on a sequence alike: large enough to at
/// least double the clean S error at the noise levels of real sensors (measured: see
/// refine_sweep.cpp).
inline double hysteresis_size_um(UndeclaredEffectDraws& draw) {
  return draw.uni(0.5, 1.5);
}

/// The sensor noise's seed for an undeclared case of `seed` (the simulators' own stream).
inline std::uint64_t undeclared_noise_seed(std::uint64_t seed) {
  return seed * 7919 + 17;
}

struct UndeclaredCase {
  FourSensorConfig cfg;
  Eigen::MatrixXd m_um;                   ///< P × 4 readings with the effect and the noise
  Eigen::MatrixXd m_clean_um;             ///< the same truth and noise without the effect
  Eigen::MatrixXd t_s;                    ///< P × 4 reading times
  Eigen::VectorXd f_um, S_um, gamma_rad;  ///< the truth (f in the separation's gauge)
  std::string description;                ///< the effect and its drawn parameters
};

/// Draws the case.  Throws std::invalid_argument for invalid options.
UndeclaredCase simulate_undeclared(UndeclaredEffect effect, const UndeclaredCaseOptions& opts);

}  // namespace errsep::core

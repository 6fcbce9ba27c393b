#include "errsep/core/four_sensor_sequence_simulation.hpp"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>

namespace errsep::core {

SequenceSimData simulate_four_sensor_sequence(const FourSensorConfig& cfg,
                                              const SlidewayTruth& truth, const ScanSequence& seq,
                                              const SequenceSimOptions& opts) {
  std::string why;
  if (!cfg.is_valid(&why)) throw std::invalid_argument("invalid configuration: " + why);
  if (!seq.is_valid(&why)) throw std::invalid_argument("invalid scan sequence: " + why);
  if (!(opts.sigma_um >= 0)) throw std::invalid_argument("sigma_um must be >= 0");
  if (!truth.f_um || !truth.S_um || !truth.gamma_rad)
    throw std::invalid_argument("simulation truth needs f, S and gamma functions");
  if (!(opts.effects.thermal_tau_s > 0)) throw std::invalid_argument("thermal_tau_s must be > 0");
  if (!std::isfinite(opts.effects.nonlinearity_c2_per_um) ||
      !std::isfinite(opts.effects.nonlinearity_mid_um))
    throw std::invalid_argument("the non-linearity's c2 and mid must be finite");
  if (!(opts.effects.hysteresis_um >= 0) || !std::isfinite(opts.effects.hysteresis_um))
    throw std::invalid_argument("the hysteresis must be finite and >= 0");
  const int P = cfg.positions(), T = seq.size();
  const auto O = cfg.offsets_mm();
  const auto& fx = opts.effects;
  std::mt19937_64 rng(opts.seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  SequenceSimData d;
  d.t_s = seq.times_s(cfg);
  d.m_um.resize(P, T);
  d.m_clean_um.resize(P, T);
  d.x_mm.resize(P);
  d.S_um.resize(P);
  d.gamma_rad.resize(P);
  for (int n = 0; n < P; ++n) {
    const double x = n * cfg.dx_mm;
    d.x_mm(n) = x;
    d.S_um(n) = truth.S_um(x);
    d.gamma_rad(n) = truth.gamma_rad(x);
  }
  Eigen::VectorXd r_clean(P);  // one traverse's noise-free Eq. (1) readings (hysteresis's sign)
  for (int k = 0; k < T; ++k) {
    const Traverse& tr = seq.traverses[static_cast<std::size_t>(k)];
    const auto c = static_cast<std::size_t>(tr.configuration);
    const double dir = direction_sign(tr.direction);
    for (int n = 0; n < P; ++n)
      r_clean(n) = four_sensor_reading_um(truth, n * cfg.dx_mm, O[c]);
    for (int n = 0; n < P; ++n) {
      const double x = n * cfg.dx_mm, t = d.t_s(n, k);
      // Eq. (1) at the traverse's zero plus noise; the effects on top of the same noisy reading.
      const double clean =
          four_sensor_reading_um(truth, x, O[c]) + truth.e_um[c] + tr.zero_shift_um;
      d.m_clean_um(n, k) = clean + opts.sigma_um * noise(rng);
      double extra =
          fx.drift_um_per_s[c] * t + fx.thermal_um[c] * (1.0 - std::exp(-t / fx.thermal_tau_s));
      if (fx.S_change_um) extra += fx.S_change_um(k, x);
      // The non-linearity acts on what the sensor reads, its zero shift included.
      extra += fx.nonlinearity_c2_per_um * (clean - fx.nonlinearity_mid_um) *
               (clean - fx.nonlinearity_mid_um);
      if (fx.hysteresis_um > 0) {
        // dr/dt = dr/dx · dx/dt: the change along x (central, one-sided at the ends) times the
        // traverse's direction.
        const double slope = r_clean(std::min(n + 1, P - 1)) - r_clean(std::max(n - 1, 0));
        extra -= fx.hysteresis_um * dir * (slope > 0 ? 1.0 : slope < 0 ? -1.0 : 0.0);
      }
      d.m_um(n, k) = d.m_clean_um(n, k) + extra;
    }
  }
  d.f_um.resize(cfg.N);
  for (int j = 0; j < cfg.N; ++j)
    d.f_um(j) = truth.f_um(j * cfg.dx_mm);
  return d;
}

}  // namespace errsep::core

#include "errsep/core/model_effect.hpp"

#include "errsep/core/effect_drift.hpp"
#include "errsep/core/effect_gain.hpp"
#include "errsep/core/effect_periodic.hpp"
#include "errsep/core/effect_sensor_offset.hpp"
#include "errsep/core/effect_slide_positioning.hpp"

namespace errsep::core {

double grid_derivative(const Eigen::VectorXd& v, double h, Eigen::Index j) {
  const Eigen::Index n = v.size();
  if (n < 2) return 0.0;
  if (j <= 0) return (v(1) - v(0)) / h;
  if (j >= n - 1) return (v(n - 1) - v(n - 2)) / h;
  return (v(j + 1) - v(j - 1)) / (2.0 * h);
}

double EffectContext::f_slope(int j) const {
  return grid_derivative(f_um, cfg.dx_mm, j);
}
double EffectContext::S_slope(int n) const {
  return grid_derivative(S_um, cfg.dx_mm, n);
}
double EffectContext::gamma_slope(int n) const {
  return grid_derivative(gamma_rad, cfg.dx_mm, n);
}

std::vector<std::unique_ptr<ModelEffect>> ModelEffect::variants(const EffectContext&) const {
  std::vector<std::unique_ptr<ModelEffect>> v;
  v.push_back(clone());
  return v;
}

double ModelEffect::effective_trials(const EffectContext&) const {
  return 1.0;
}

std::vector<std::unique_ptr<ModelEffect>> default_effect_library() {
  std::vector<std::unique_ptr<ModelEffect>> lib;
  lib.push_back(std::make_unique<SensorOffsetEffect>());
  lib.push_back(std::make_unique<GainEffect>());
  lib.push_back(std::make_unique<DriftEffect>());
  lib.push_back(std::make_unique<SlidePositioningEffect>());
  lib.push_back(std::make_unique<PeriodicEffect>());
  return lib;
}

}  // namespace errsep::core

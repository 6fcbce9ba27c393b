#include "errsep/core/effect_periodic.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "errsep/core/effect_slide_positioning.hpp"
#include "errsep/core/residual_analysis.hpp"

namespace errsep::core {

namespace {
constexpr int kOversampling = 4;
// Frequencies k/(os·L), periods from half the travel down to 3Δx.
int first_index(const FourSensorConfig&) {
  return 2 * kOversampling;
}
int last_index(const FourSensorConfig& cfg) {
  return static_cast<int>(std::floor(kOversampling * cfg.travel_mm() / (3.0 * cfg.dx_mm)));
}
}  // namespace

std::string PeriodicEffect::description() const {
  char buf[160];
  std::snprintf(buf, sizeof buf,
                "periodic slide positioning error, period %.4g mm: dx = a cos(2pi x/l) + b "
                "sin(2pi x/l)",
                period_mm_);
  return buf;
}

double PeriodicEffect::period_mm(const Eigen::VectorXd& p) const {
  return std::max(period_mm_ + (p.size() > 2 ? p(2) : 0.0), 0.5 * period_mm_);
}

std::string PeriodicEffect::description(const Eigen::VectorXd& p) const {
  char buf[200];
  std::snprintf(buf, sizeof buf,
                "periodic slide positioning error, period %.5g mm (refined from %.4g mm): dx = a "
                "cos(2pi x/l) + b sin(2pi x/l)",
                period_mm(p), period_mm_);
  return buf;
}

Eigen::MatrixXd PeriodicEffect::basis(const FourSensorConfig& cfg, const Eigen::VectorXd& p) const {
  const int P = cfg.positions();
  const double l = period_mm(p);
  const double a = p.size() > 0 ? p(0) : 0.0, b = p.size() > 1 ? p(1) : 0.0;
  Eigen::MatrixXd phi(P, 3);
  for (int n = 0; n < P; ++n) {
    const double x = n * cfg.dx_mm, w = 2.0 * std::numbers::pi * x / l;
    phi(n, 0) = std::cos(w);
    phi(n, 1) = std::sin(w);
    // ∂/∂λ of a·cos(2πx/λ) + b·sin(2πx/λ) = (2πx/λ²)·(a·sin − b·cos).
    phi(n, 2) = 2.0 * std::numbers::pi * x / (l * l) * (a * std::sin(w) - b * std::cos(w));
  }
  return phi;
}

Eigen::MatrixXd PeriodicEffect::correction_um(const Eigen::VectorXd& p,
                                              const EffectContext& ctx) const {
  return slide_positioning_correction_um(basis(ctx.cfg, p).leftCols(2) * p.head(2), ctx);
}

Eigen::MatrixXd PeriodicEffect::jacobian(const Eigen::VectorXd& p, const EffectContext& ctx) const {
  const Eigen::MatrixXd phi = basis(ctx.cfg, p);
  return slide_positioning_jacobian(phi, ctx, phi.leftCols(2) * p.head(2));
}

Eigen::MatrixXd PeriodicEffect::f_shift_mm(const Eigen::VectorXd& p,
                                           const FourSensorConfig& cfg) const {
  return slide_positioning_f_shift_mm(basis(cfg, p).leftCols(2) * p.head(2));
}

std::vector<std::unique_ptr<ModelEffect>> PeriodicEffect::variants(const EffectContext& ctx) const {
  std::vector<std::unique_ptr<ModelEffect>> v;
  if (period_mm_ > 0) {  // a period already chosen (the effect is in the model)
    v.push_back(clone());
    return v;
  }
  const double L = ctx.cfg.travel_mm();
  for (int k = first_index(ctx.cfg); k <= last_index(ctx.cfg); ++k)
    v.push_back(std::make_unique<PeriodicEffect>(kOversampling * L / k));
  // The dominant period of the residual spectrum, when it falls in the searched range.
  if (ctx.residual_um.rows() >= 8) {
    double q = 0, ratio = 0;
    Eigen::VectorXd power;
    whiteness_statistics(ctx.residual_um, 1, &q, &ratio, &power);
    Eigen::Index kmax = 0;
    if (power.size() > 0) {
      power.maxCoeff(&kmax);
      const double period = ctx.residual_um.rows() * ctx.cfg.dx_mm / static_cast<double>(kmax + 1);
      if (period >= 3.0 * ctx.cfg.dx_mm && period <= 0.5 * L)
        v.push_back(std::make_unique<PeriodicEffect>(period));
    }
  }
  return v;
}

double PeriodicEffect::effective_trials(const EffectContext& ctx) const {
  if (period_mm_ > 0) return 1.0;
  const int n = last_index(ctx.cfg) - first_index(ctx.cfg) + 1;
  return std::max(1.0, static_cast<double>(n) / kOversampling);
}

std::unique_ptr<ModelEffect> PeriodicEffect::clone() const {
  return std::make_unique<PeriodicEffect>(*this);
}

std::string PeriodicEffect::implausibility(const Eigen::VectorXd& p,
                                           const EffectContext& ctx) const {
  // A periodic positioning error is a slide positioning error: the same bound.
  return slide_positioning_implausibility(basis(ctx.cfg, p).leftCols(2) * p.head(2), ctx.cfg);
}

}  // namespace errsep::core

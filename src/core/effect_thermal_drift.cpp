#include "errsep/core/effect_thermal_drift.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace errsep::core {

namespace {
constexpr int kGridCount = 10;
}  // namespace

std::string ThermalDriftEffect::description() const {
  char buf[160];
  std::snprintf(buf, sizeof buf,
                "first-order thermal drift per configuration, tau = %.4g s + dtau: m_i -> m_i - "
                "a_i*(1 - exp(-t/tau))",
                tau0_s_);
  return buf;
}

std::string ThermalDriftEffect::description(const Eigen::VectorXd& p) const {
  char buf[200];
  std::snprintf(buf, sizeof buf,
                "first-order thermal drift per configuration, tau = %.4g s (refined from %.4g s): "
                "m_i -> m_i - a_i*(1 - exp(-t/tau))",
                tau_s(p), tau0_s_);
  return buf;
}

double ThermalDriftEffect::tau_s(const Eigen::VectorXd& p) const {
  // A Gauss–Newton step may overshoot; τ stays positive (the step control then halves it).
  return std::max(tau0_s_ + (p.size() > 4 ? p(4) : 0.0), 0.05 * tau0_s_);
}

std::vector<double> ThermalDriftEffect::tau_grid_s(const Eigen::MatrixXd& t_s, int count) {
  std::vector<double> g;
  if (t_s.size() == 0 || count < 1) return g;
  const double span = std::max(t_s.maxCoeff() - t_s.minCoeff(), 1e-9);
  const double lo = span / 30.0, hi = 2.0 * span;
  for (int k = 0; k < count; ++k)
    g.push_back(count == 1 ? lo : lo * std::pow(hi / lo, static_cast<double>(k) / (count - 1)));
  return g;
}

Eigen::MatrixXd ThermalDriftEffect::correction_um(const Eigen::VectorXd& p,
                                                  const EffectContext& ctx) const {
  const double tau = tau_s(p), t0 = ctx.t_s.minCoeff();
  Eigen::MatrixXd c(ctx.t_s.rows(), 4);
  for (int i = 0; i < 4; ++i)
    c.col(i) = p(i) * (1.0 - (-(ctx.t_s.col(i).array() - t0) / tau).exp()).matrix();
  return c;
}

Eigen::MatrixXd ThermalDriftEffect::jacobian(const Eigen::VectorXd& p,
                                             const EffectContext& ctx) const {
  const Eigen::Index P = ctx.t_s.rows();
  const double tau = tau_s(p), t0 = ctx.t_s.minCoeff();
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(4 * P, 5);
  for (Eigen::Index n = 0; n < P; ++n)
    for (int i = 0; i < 4; ++i) {
      const double s = ctx.t_s(n, i) - t0, e = std::exp(-s / tau);
      J(4 * n + i, i) = 1.0 - e;
      // ∂/∂τ of a_i·(1 − exp(−s/τ)) = −a_i·(s/τ²)·exp(−s/τ).
      J(4 * n + i, 4) = -p(i) * s / (tau * tau) * e;
    }
  return J;
}

std::vector<std::unique_ptr<ModelEffect>> ThermalDriftEffect::variants(
    const EffectContext& ctx) const {
  std::vector<std::unique_ptr<ModelEffect>> v;
  if (tau0_s_ > 0) {
    v.push_back(clone());
    return v;
  }
  for (double tau : tau_grid_s(ctx.t_s, kGridCount))
    v.push_back(std::make_unique<ThermalDriftEffect>(tau));
  return v;
}

double ThermalDriftEffect::effective_trials(const EffectContext&) const {
  // Neighbouring grid values give strongly correlated columns, so counting every one is
  // conservative (fewer false additions on clean data, a little less power).
  return tau0_s_ > 0 ? 1.0 : static_cast<double>(kGridCount);
}

std::unique_ptr<ModelEffect> ThermalDriftEffect::clone() const {
  return std::make_unique<ThermalDriftEffect>(*this);
}

}  // namespace errsep::core

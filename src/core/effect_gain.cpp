#include "errsep/core/effect_gain.hpp"

#include <cmath>
#include <cstdio>

namespace errsep::core {

std::string GainEffect::description() const {
  return "gain error per configuration relative to configuration 1: m_i -> m_i/(1+g_i)";
}

Eigen::MatrixXd GainEffect::correction_um(const Eigen::VectorXd& p,
                                          const EffectContext& ctx) const {
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(ctx.m_um.rows(), 4);
  for (int i = 1; i < 4; ++i)
    c.col(i) = ctx.m_um.col(i) * (p(i - 1) / (1.0 + p(i - 1)));  // m − m/(1+g)
  return c;
}

Eigen::MatrixXd GainEffect::jacobian(const Eigen::VectorXd& p, const EffectContext& ctx) const {
  // ∂(m − m/(1+g))/∂g = m/(1+g)², with m replaced by the fitted (noise-free) reading (1+g)·m̂:
  // a regressor built from the noisy readings would correlate with the residual and make the
  // F-test find gains in clean data.
  const Eigen::Index P = ctx.m_um.rows();
  const auto O = ctx.cfg.offsets_mm();
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(4 * P, 3);
  for (int i = 1; i < 4; ++i) {
    const std::size_t si = static_cast<std::size_t>(i);
    for (Eigen::Index n = 0; n < P; ++n) {
      const double x = static_cast<double>(n) * ctx.cfg.dx_mm;
      const double fitted =
          ctx.f_at(x + O[si]) + ctx.S_um(n) + 1000.0 * O[si] * ctx.gamma_rad(n) + ctx.e_um(i);
      J(4 * n + i, i - 1) = fitted / (1.0 + p(i - 1));
    }
  }
  return J;
}

std::unique_ptr<ModelEffect> GainEffect::clone() const {
  return std::make_unique<GainEffect>(*this);
}

std::string GainEffect::implausibility(const Eigen::VectorXd& p, const EffectContext&) const {
  // Displacement sensors (capacitive, inductive, laser triangulation) are calibrated to within a
  // percent or two of their nominal sensitivity; a gain off by more than 10 % relative to
  // configuration 1 is a wrong range setting or a broken sensor that a check against a gauge
  // block shows before any scan, not an error the separation should absorb.
  constexpr double kMaxGain = 0.10;
  std::string why;
  for (Eigen::Index j = 0; j < p.size(); ++j)
    if (!(std::abs(p(j)) <= kMaxGain)) {
      char buf[80];
      std::snprintf(buf, sizeof buf, "%s|g%d| = %.4g > %.2g", why.empty() ? "" : ", ",
                    static_cast<int>(j) + 2, std::abs(p(j)), kMaxGain);
      why += buf;
    }
  return why;
}

}  // namespace errsep::core

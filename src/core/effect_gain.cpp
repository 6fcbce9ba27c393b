#include "errsep/core/effect_gain.hpp"

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
  const Eigen::Index P = ctx.m_um.rows();
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(4 * P, 3);
  for (int i = 1; i < 4; ++i) {
    const double s = 1.0 / ((1.0 + p(i - 1)) * (1.0 + p(i - 1)));  // ∂(m − m/(1+g))/∂g
    for (Eigen::Index n = 0; n < P; ++n)
      J(4 * n + i, i - 1) = ctx.m_um(n, i) * s;
  }
  return J;
}

std::unique_ptr<ModelEffect> GainEffect::clone() const {
  return std::make_unique<GainEffect>(*this);
}

}  // namespace errsep::core

#include "errsep/core/effect_drift.hpp"

namespace errsep::core {

std::string DriftEffect::description() const {
  return "linear drift in time per configuration: m_i -> m_i - a_i*t_i";
}

Eigen::MatrixXd DriftEffect::correction_um(const Eigen::VectorXd& p,
                                           const EffectContext& ctx) const {
  Eigen::MatrixXd c(ctx.t_s.rows(), 4);
  for (int i = 0; i < 4; ++i)
    c.col(i) = ctx.t_s.col(i) * p(i);
  return c;
}

Eigen::MatrixXd DriftEffect::jacobian(const Eigen::VectorXd&, const EffectContext& ctx) const {
  const Eigen::Index P = ctx.t_s.rows();
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(4 * P, 4);
  for (Eigen::Index n = 0; n < P; ++n)
    for (int i = 0; i < 4; ++i)
      J(4 * n + i, i) = ctx.t_s(n, i);
  return J;
}

std::unique_ptr<ModelEffect> DriftEffect::clone() const {
  return std::make_unique<DriftEffect>(*this);
}

}  // namespace errsep::core

#include "errsep/core/effect_sensor_offset.hpp"

namespace errsep::core {

std::string SensorOffsetEffect::description() const {
  return "sensor positioning error (PE1): actual spacings D_i + dD_i, signature dO_i*f'(x+O_i)";
}

namespace {
// ∂m_i(x_n)/∂δO_i in µm/mm: the slope of f at the sensor and the tilt term of Eq. (1).
double slope_um_per_mm(const EffectContext& ctx, Eigen::Index n, int i) {
  const auto k = ctx.cfg.offsets_samples();
  return ctx.f_slope(static_cast<int>(n) + k[static_cast<std::size_t>(i)]) +
         1000.0 * ctx.gamma_rad(n);
}
}  // namespace

Eigen::MatrixXd SensorOffsetEffect::correction_um(const Eigen::VectorXd& p,
                                                  const EffectContext& ctx) const {
  const Eigen::Index P = ctx.m_um.rows();
  const double dO[4] = {0.0, p(0), p(0) + p(1), p(0) + p(1) + p(2)};
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(P, 4);
  for (Eigen::Index n = 0; n < P; ++n)
    for (int i = 1; i < 4; ++i)
      c(n, i) = dO[i] * slope_um_per_mm(ctx, n, i);
  return c;
}

Eigen::MatrixXd SensorOffsetEffect::jacobian(const Eigen::VectorXd&,
                                             const EffectContext& ctx) const {
  const Eigen::Index P = ctx.m_um.rows();
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(4 * P, 3);
  // δO_i = Σ_{j<=i} δD_j: configuration i depends on δD_2..δD_i.
  for (Eigen::Index n = 0; n < P; ++n)
    for (int i = 1; i < 4; ++i) {
      const double s = slope_um_per_mm(ctx, n, i);
      for (int j = 1; j <= i; ++j)
        J(4 * n + i, j - 1) = s;
    }
  return J;
}

std::unique_ptr<ModelEffect> SensorOffsetEffect::clone() const {
  return std::make_unique<SensorOffsetEffect>(*this);
}

}  // namespace errsep::core

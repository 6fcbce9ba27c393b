#include "errsep/core/effect_sensor_offset.hpp"

#include <array>
#include <cmath>
#include <cstdio>

namespace errsep::core {

std::string SensorOffsetEffect::description() const {
  return "sensor positioning error (PE1): actual spacings D_i + dD_i, signature dO_i*f'(x+O_i)";
}

namespace {
std::array<double, 4> offsets_error(const Eigen::VectorXd& p) {
  return {0.0, p(0), p(0) + p(1), p(0) + p(1) + p(2)};
}
// ∂m_i(x_n)/∂δO_i in µm/mm at the actual position: slope of f there and the tilt term of Eq. (1).
double slope_um_per_mm(const EffectContext& ctx, Eigen::Index n, int i, double dO) {
  const double y = n * ctx.cfg.dx_mm + ctx.cfg.offsets_mm()[static_cast<std::size_t>(i)] + dO;
  return ctx.f_slope_at(y) + 1000.0 * ctx.gamma_rad(n);
}
}  // namespace

Eigen::MatrixXd SensorOffsetEffect::correction_um(const Eigen::VectorXd& p,
                                                  const EffectContext& ctx) const {
  const Eigen::Index P = ctx.m_um.rows();
  const auto dO = offsets_error(p);
  const auto O = ctx.cfg.offsets_mm();
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(P, 4);
  // Not linearised: the reading of Eq. (1) at the actual offset minus the one at the nominal.
  for (Eigen::Index n = 0; n < P; ++n)
    for (std::size_t i = 1; i < 4; ++i) {
      const double y = n * ctx.cfg.dx_mm + O[i];
      c(n, static_cast<Eigen::Index>(i)) =
          ctx.f_at(y + dO[i]) - ctx.f_at(y) + 1000.0 * dO[i] * ctx.gamma_rad(n);
    }
  return c;
}

Eigen::MatrixXd SensorOffsetEffect::jacobian(const Eigen::VectorXd& p,
                                             const EffectContext& ctx) const {
  const Eigen::Index P = ctx.m_um.rows();
  const auto dO = offsets_error(p);
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(4 * P, 3);
  // δO_i = Σ_{j<=i} δD_j: configuration i depends on δD_2..δD_i.
  for (Eigen::Index n = 0; n < P; ++n)
    for (int i = 1; i < 4; ++i) {
      const double s = slope_um_per_mm(ctx, n, i, dO[static_cast<std::size_t>(i)]);
      for (int j = 1; j <= i; ++j)
        J(4 * n + i, j - 1) = s;
    }
  return J;
}

Eigen::MatrixXd SensorOffsetEffect::f_shift_mm(const Eigen::VectorXd& p,
                                               const FourSensorConfig& cfg) const {
  const auto dO = offsets_error(p);
  Eigen::MatrixXd s(cfg.positions(), 4);
  for (int i = 0; i < 4; ++i)
    s.col(i).setConstant(dO[static_cast<std::size_t>(i)]);
  return s;
}

Eigen::Vector4d SensorOffsetEffect::lever_arm_error_mm(const Eigen::VectorXd& p) const {
  const auto dO = offsets_error(p);
  return Eigen::Vector4d(dO[0], dO[1], dO[2], dO[3]);
}

std::unique_ptr<ModelEffect> SensorOffsetEffect::clone() const {
  return std::make_unique<SensorOffsetEffect>(*this);
}

std::string SensorOffsetEffect::implausibility(const Eigen::VectorXd& p,
                                               const EffectContext& ctx) const {
  // The sensor holder is machined to tenths of a millimetre; a spacing off by a quarter of its
  // nominal value (1.25 mm of 5 mm, 6.25 mm of 25 mm) is a gross assembly or configuration
  // error that a ruler finds before any scan, and beyond the linearisation in δO the effect's
  // signature rests on (δO small against the scale on which f varies, see the header).
  constexpr double kMaxFraction = 0.25;
  const std::array<double, 3> D_mm = {ctx.cfg.s2 * ctx.cfg.dx_mm, ctx.cfg.s3 * ctx.cfg.dx_mm,
                                      ctx.cfg.s4 * ctx.cfg.dx_mm};
  std::string why;
  for (Eigen::Index j = 0; j < p.size() && j < 3; ++j) {
    const double limit_mm = kMaxFraction * D_mm[static_cast<std::size_t>(j)];
    if (!(std::abs(p(j)) <= limit_mm)) {
      char buf[100];
      std::snprintf(buf, sizeof buf, "%s|dD%d| = %.4g mm > %.2g of the nominal %.4g mm",
                    why.empty() ? "" : ", ", static_cast<int>(j) + 2, std::abs(p(j)), kMaxFraction,
                    D_mm[static_cast<std::size_t>(j)]);
      why += buf;
    }
  }
  return why;
}

}  // namespace errsep::core

#include "errsep/core/effect_slide_positioning.hpp"

#include <cmath>
#include <cstdio>
#include <string>

namespace errsep::core {

namespace {
// Eq. (1) with the slide at x (mm), from the current estimate.
double reading(const EffectContext& ctx, double x, std::size_t i) {
  const double O = ctx.cfg.offsets_mm()[i];
  return ctx.f_at(x + O) + ctx.S_at(x) + 1000.0 * O * ctx.gamma_at(x);
}
// ∂m_i/∂x in µm/mm at slide position x.
double reading_slope(const EffectContext& ctx, double x, std::size_t i) {
  const double O = ctx.cfg.offsets_mm()[i];
  return ctx.f_slope_at(x + O) + ctx.S_slope_at(x) + 1000.0 * O * ctx.gamma_slope_at(x);
}
}  // namespace

Eigen::MatrixXd slide_positioning_jacobian(const Eigen::MatrixXd& phi, const EffectContext& ctx,
                                           const Eigen::VectorXd& dx_um) {
  const Eigen::Index P = phi.rows();
  Eigen::MatrixXd J(4 * P, phi.cols());
  for (Eigen::Index n = 0; n < P; ++n)
    for (std::size_t i = 0; i < 4; ++i) {
      const double x = n * ctx.cfg.dx_mm + (dx_um.size() ? 1e-3 * dx_um(n) : 0.0);
      const double s = 1e-3 * reading_slope(ctx, x, i);  // δx in µm
      J.row(4 * n + static_cast<Eigen::Index>(i)) = phi.row(n) * s;
    }
  return J;
}

Eigen::MatrixXd slide_positioning_f_shift_mm(const Eigen::VectorXd& dx_um) {
  Eigen::MatrixXd s(dx_um.size(), 4);
  for (int i = 0; i < 4; ++i)
    s.col(i) = 1e-3 * dx_um;
  return s;
}

Eigen::MatrixXd slide_positioning_correction_um(const Eigen::VectorXd& dx_um,
                                                const EffectContext& ctx) {
  const Eigen::Index P = dx_um.size();
  Eigen::MatrixXd c(P, 4);
  // Not linearised: Eq. (1) at the actual slide position minus at the commanded one.
  for (Eigen::Index n = 0; n < P; ++n)
    for (std::size_t i = 0; i < 4; ++i) {
      const double x = n * ctx.cfg.dx_mm;
      c(n, static_cast<Eigen::Index>(i)) =
          reading(ctx, x + 1e-3 * dx_um(n), i) - reading(ctx, x, i);
    }
  return c;
}

std::string SlidePositioningEffect::description() const {
  return "slide positioning error along x (PE2): dx(x) = sum of Legendre P_1..P_" +
         std::to_string(degree_) + " on the travel, signature dx(x)*f'(x+O_i)";
}

std::vector<std::string> SlidePositioningEffect::parameter_names() const {
  std::vector<std::string> n;
  for (int k = 1; k <= degree_; ++k)
    n.push_back("c" + std::to_string(k) + "_um");
  return n;
}

Eigen::MatrixXd SlidePositioningEffect::basis(const FourSensorConfig& cfg) const {
  const int P = cfg.positions();
  const double L = cfg.travel_mm();
  Eigen::MatrixXd phi(P, degree_);
  for (int n = 0; n < P; ++n) {
    const double u = 2.0 * n * cfg.dx_mm / L - 1.0;
    double pm1 = 1.0, p = u;  // Bonnet's recursion
    for (int k = 1; k <= degree_; ++k) {
      phi(n, k - 1) = p;
      const double next = ((2.0 * k + 1.0) * u * p - k * pm1) / (k + 1.0);
      pm1 = p;
      p = next;
    }
  }
  return phi;
}

Eigen::MatrixXd SlidePositioningEffect::correction_um(const Eigen::VectorXd& p,
                                                      const EffectContext& ctx) const {
  return slide_positioning_correction_um(basis(ctx.cfg) * p, ctx);
}

Eigen::MatrixXd SlidePositioningEffect::jacobian(const Eigen::VectorXd& p,
                                                 const EffectContext& ctx) const {
  const Eigen::MatrixXd phi = basis(ctx.cfg);
  return slide_positioning_jacobian(phi, ctx, phi * p);
}

Eigen::MatrixXd SlidePositioningEffect::f_shift_mm(const Eigen::VectorXd& p,
                                                   const FourSensorConfig& cfg) const {
  return slide_positioning_f_shift_mm(basis(cfg) * p);
}

std::unique_ptr<ModelEffect> SlidePositioningEffect::clone() const {
  return std::make_unique<SlidePositioningEffect>(*this);
}

std::string slide_positioning_implausibility(const Eigen::VectorXd& dx_um,
                                             const FourSensorConfig& cfg) {
  if (dx_um.size() == 0) return {};
  const double limit_um = 0.5 * 1000.0 * cfg.dx_mm;
  Eigen::Index n = 0;
  const double worst = dx_um.cwiseAbs().maxCoeff(&n);
  if (std::isfinite(worst) && worst <= limit_um) return {};
  char buf[160];
  std::snprintf(buf, sizeof buf, "|dx| = %.4g um at x = %.4g mm > half the sample interval %.4g um",
                worst, static_cast<double>(n) * cfg.dx_mm, limit_um);
  return buf;
}

std::string SlidePositioningEffect::implausibility(const Eigen::VectorXd& p,
                                                   const EffectContext& ctx) const {
  return slide_positioning_implausibility(basis(ctx.cfg) * p, ctx.cfg);
}

}  // namespace errsep::core

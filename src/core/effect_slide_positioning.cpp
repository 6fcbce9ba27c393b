#include "errsep/core/effect_slide_positioning.hpp"

#include <string>

namespace errsep::core {

namespace {
// ∂m_i(x_n)/∂x in µm/mm (Eq. 1 differentiated along the slide).
double reading_slope(const EffectContext& ctx, Eigen::Index n, int i) {
  const auto k = ctx.cfg.offsets_samples();
  const auto O = ctx.cfg.offsets_mm();
  const int ni = static_cast<int>(n);
  return ctx.f_slope(ni + k[static_cast<std::size_t>(i)]) + ctx.S_slope(ni) +
         1000.0 * O[static_cast<std::size_t>(i)] * ctx.gamma_slope(ni);
}
}  // namespace

Eigen::MatrixXd slide_positioning_jacobian(const Eigen::MatrixXd& phi, const EffectContext& ctx) {
  const Eigen::Index P = phi.rows();
  Eigen::MatrixXd J(4 * P, phi.cols());
  for (Eigen::Index n = 0; n < P; ++n)
    for (int i = 0; i < 4; ++i) {
      const double s = 1e-3 * reading_slope(ctx, n, i);  // δx in µm
      J.row(4 * n + i) = phi.row(n) * s;
    }
  return J;
}

Eigen::MatrixXd slide_positioning_correction_um(const Eigen::VectorXd& dx_um,
                                                const EffectContext& ctx) {
  const Eigen::Index P = dx_um.size();
  Eigen::MatrixXd c(P, 4);
  for (Eigen::Index n = 0; n < P; ++n)
    for (int i = 0; i < 4; ++i)
      c(n, i) = 1e-3 * dx_um(n) * reading_slope(ctx, n, i);
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

Eigen::MatrixXd SlidePositioningEffect::jacobian(const Eigen::VectorXd&,
                                                 const EffectContext& ctx) const {
  return slide_positioning_jacobian(basis(ctx.cfg), ctx);
}

std::unique_ptr<ModelEffect> SlidePositioningEffect::clone() const {
  return std::make_unique<SlidePositioningEffect>(*this);
}

}  // namespace errsep::core

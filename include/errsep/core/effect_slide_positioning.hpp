#pragma once
// Positioning error of the slide along x (Zhao 2019 Eq. 20, PE2): commanded to x_n, the slide
// stands at x_n + δx(x_n) in every traverse, and everything that moves with it is sampled there:
//
//   m_i(x_n) ≈ Eq. (1) + δx(x_n)·(f′(x_n + O_i) + S′(x_n) + O_i·γ′(x_n))
//
// The S′ and O_i·γ′ parts are, per position, affine in O_i: S and γ absorb them (the separated
// S, γ are those at the actual positions) and only δx·f′ is visible in the residual.  The
// correction uses all three, so the solver on corrected data returns S and γ at the commanded x.
// δx is smooth: a sum of Legendre polynomials of degree 1..d on the travel (a constant δx shifts
// the whole reference surface and is not identifiable; degree 0 is left out).
#include "errsep/core/model_effect.hpp"

namespace errsep::core {

/// Columns of J for δx = Σ_k p_k·φ_k(x_n) (φ: P × k, δx in µm), at the current δx (µm, P).
Eigen::MatrixXd slide_positioning_jacobian(const Eigen::MatrixXd& phi, const EffectContext& ctx,
                                           const Eigen::VectorXd& dx_um);
/// The shift of f's sampling point for δx(x_n) given per position (µm): δx/1000 in all four
/// columns (ModelEffect::f_shift_mm).
Eigen::MatrixXd slide_positioning_f_shift_mm(const Eigen::VectorXd& dx_um);
/// The correction for δx(x_n) given per position (µm).
Eigen::MatrixXd slide_positioning_correction_um(const Eigen::VectorXd& dx_um,
                                                const EffectContext& ctx);

/// Plausibility of a slide positioning error δx(x_n) (µm, P): empty, or why not.  |δx| must stay
/// below half the sample interval: the slide is sampled every Δx by its scale or encoder, and an
/// error of half an interval or more would assign readings to the wrong grid point, a counting
/// fault of the acquisition rather than a positioning error of the slideway (real slideways:
/// micrometres to tens of micrometres over the travel).
std::string slide_positioning_implausibility(const Eigen::VectorXd& dx_um,
                                             const FourSensorConfig& cfg);

class SlidePositioningEffect final : public ModelEffect {
 public:
  explicit SlidePositioningEffect(int degree = 3) : degree_(degree) {}
  std::string name() const override { return "pe2"; }
  std::string description() const override;
  std::vector<std::string> parameter_names() const override;
  Eigen::MatrixXd correction_um(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  Eigen::MatrixXd jacobian(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  Eigen::MatrixXd f_shift_mm(const Eigen::VectorXd& p, const FourSensorConfig& cfg) const override;
  std::string implausibility(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  std::unique_ptr<ModelEffect> clone() const override;
  /// φ_k(x_n), P × degree: Legendre P_k(2x/L − 1), k = 1..degree.
  Eigen::MatrixXd basis(const FourSensorConfig& cfg) const;

 private:
  int degree_;
};

}  // namespace errsep::core

#pragma once
// A straightness S(x) or tilt γ(x) that does not repeat between the four traverses of the
// single-sensor system (the sensor is moved to configuration i and the slide traverses once per
// configuration; Zhao 2019 Eq. 1 assumes the same S and γ in every traverse):
//
//   m_i(x_n) = Eq. (1) + ΔS_i(x_n) + O_i·Δγ_i(x_n)
//
// ΔS_i and O_i·Δγ_i enter configuration i's readings in the same way, so one scan cannot tell a
// non-repeating straightness from a non-repeating tilt: the effect is parametrised as the
// equivalent h_i(x) = ΔS_i(x) + O_i·Δγ_i(x) (reported as µm of S), a sum of Legendre polynomials
// P_k(2x/L − 1) of degree k = 1..K per traverse (library: K = 4, 16 parameters).
//
// Identifiability (checked in tests/core/refine_effects_more.cpp).  Degree 0 (an offset of S or
// γ per traverse) is invisible: e absorbs it.  Per position, S and γ absorb the part of
// (h_1..h_4) in span{1, O} (a change common to all traverses, or one proportional to the offset),
// and a polynomial reference surface f of degree k + 2 absorbs one more direction per degree
// (f(x + O) = … + x^k·O² + …).  Each degree k ≥ 1 thus leaves one combination of the four
// traverses: K identifiable directions of the 4K parameters, all well determined (relative
// singular values ≥ 0.9 for K ≤ 5).  Degree 1 (a per-traverse slope) is, with scan-order times
// t_i = i·T + x/v, exactly the linear drift's column (effect_drift.hpp): with the drift in the
// model K − 1 directions remain, and the drift adds nothing after this effect.  A non-repeat on
// one traverse alone is partly in the null space (a P2 + P3/2 bow on traverse 3: 47 % of its
// parameter norm identifiable); the part that is not identifiable stays in Ŝ, γ̂, f̂ and the
// minimum-norm correction cannot remove it (leaving degree 1 out, K = 2..4, would leave one
// direction at relative singular value 0.06, whose noise then goes into the profiles).
#include "errsep/core/model_effect.hpp"

namespace errsep::core {

class TraverseEffect final : public ModelEffect {
 public:
  /// Degrees k_min..K of the per-traverse polynomials.
  explicit TraverseEffect(int min_degree = 1, int max_degree = 4)
      : min_degree_(min_degree), max_degree_(max_degree) {}
  std::string name() const override { return "traverse"; }
  std::string description() const override;
  /// dS<i>_P<k>_um, configuration-major (i = 1..4, k = k_min..K).
  std::vector<std::string> parameter_names() const override;
  Eigen::MatrixXd correction_um(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  Eigen::MatrixXd jacobian(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  std::unique_ptr<ModelEffect> clone() const override;
  /// P_k(2x_n/L − 1), P × (K − k_min + 1), k = k_min..K (k_min = 0 allowed, for the checks).
  Eigen::MatrixXd basis(const FourSensorConfig& cfg) const;
  int min_degree() const { return min_degree_; }
  int max_degree() const { return max_degree_; }

 private:
  int min_degree_, max_degree_;
};

}  // namespace errsep::core

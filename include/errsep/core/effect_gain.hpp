#pragma once
// Gain error per configuration: configuration i reads (1 + g_i)·(f(x+O_i) + S + O_i·γ + e_i).
// A gain common to all four configurations scales f, S, γ and e together and is not identifiable
// from the readings, so g_1 = 0 (gains relative to configuration 1).  Correction m_i/(1 + g_i).
#include "errsep/core/model_effect.hpp"

namespace errsep::core {

class GainEffect final : public ModelEffect {
 public:
  std::string name() const override { return "gain"; }
  std::string description() const override;
  std::vector<std::string> parameter_names() const override { return {"g2", "g3", "g4"}; }
  Eigen::MatrixXd correction_um(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  Eigen::MatrixXd jacobian(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  std::string implausibility(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  std::unique_ptr<ModelEffect> clone() const override;
};

}  // namespace errsep::core

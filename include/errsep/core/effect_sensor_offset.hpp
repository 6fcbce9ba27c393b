#pragma once
// Sensor positioning error of each configuration (Zhao 2019 section 3, PE1): the actual spacings
// are D_i + δD_i, so configuration i sits at O_i + δO_i with δO_2 = δD_2, δO_3 = δD_2 + δD_3,
// δO_4 = δD_2 + δD_3 + δD_4.  Linearised in δO (δO ≪ the scale on which f varies):
//
//   m_i(x_n) ≈ Eq. (1) + δO_i·(f′(x_n + O_i) + γ(x_n))      (µm, f′ in µm/mm, γ in µm/mm)
//
// so the signature is the slope of the reference surface seen by each configuration.  A linear f
// gives a constant per configuration (absorbed by e_i): PE1 is only visible through the curvature
// and waviness of f.
#include "errsep/core/model_effect.hpp"

namespace errsep::core {

class SensorOffsetEffect final : public ModelEffect {
 public:
  std::string name() const override { return "pe1"; }
  std::string description() const override;
  std::vector<std::string> parameter_names() const override {
    return {"dD2_mm", "dD3_mm", "dD4_mm"};
  }
  Eigen::MatrixXd correction_um(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  Eigen::MatrixXd jacobian(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  /// δO_i for every position of configuration i.
  Eigen::MatrixXd f_shift_mm(const Eigen::VectorXd& p, const FourSensorConfig& cfg) const override;
  /// δO_i: the sensor moved, so did the lever arm of γ.
  Eigen::Vector4d lever_arm_error_mm(const Eigen::VectorXd& p) const override;
  std::string implausibility(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  std::unique_ptr<ModelEffect> clone() const override;
};

}  // namespace errsep::core

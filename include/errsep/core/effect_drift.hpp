#pragma once
// Linear drift of the sensor in time, one rate per configuration: m_i(x_n) += a_i·t_i(x_n).
//
// Identifiability: with the scan-order times of a single-sensor system (t = i·T + x/v) a drift
// common to all configurations (a_i = a) is a function of x alone plus a constant per
// configuration — S and e absorb it — and a drift proportional to the offset (a_i = b·O_i) is
// absorbed by γ and e.  Only the part of (a_1..a_4) orthogonal to span{1, O} is identifiable from
// one scan; the refinement reports that part (minimum-norm estimate) and the null directions.
// Recorded times that are not of that form (bidirectional traverses, pauses) identify more.
#include "errsep/core/model_effect.hpp"

namespace errsep::core {

class DriftEffect final : public ModelEffect {
 public:
  std::string name() const override { return "drift"; }
  std::string description() const override;
  std::vector<std::string> parameter_names() const override {
    return {"a1_um_per_s", "a2_um_per_s", "a3_um_per_s", "a4_um_per_s"};
  }
  Eigen::MatrixXd correction_um(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  Eigen::MatrixXd jacobian(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  std::unique_ptr<ModelEffect> clone() const override;
};

}  // namespace errsep::core

#pragma once
// A periodic positioning error of the slide (lead-screw pitch error, encoder interpolation error):
// δx(x) = a·cos(2πx/λ) + b·sin(2πx/λ), with the signature of effect_slide_positioning.hpp.  The
// period λ is not a free parameter of the fit: `variants` returns one effect per period on a grid
// (4× oversampled in frequency, periods from 3Δx to half the travel, plus the dominant period of
// the residual spectrum), the loop keeps the best, and its p-value is corrected for the number of
// independent periods tried (`effective_trials`).
#include "errsep/core/model_effect.hpp"

namespace errsep::core {

class PeriodicEffect final : public ModelEffect {
 public:
  explicit PeriodicEffect(double period_mm = 0.0) : period_mm_(period_mm) {}
  std::string name() const override { return "periodic"; }
  std::string description() const override;
  std::vector<std::string> parameter_names() const override { return {"a_cos_um", "b_sin_um"}; }
  Eigen::MatrixXd correction_um(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  Eigen::MatrixXd jacobian(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  Eigen::MatrixXd f_shift_mm(const Eigen::VectorXd& p, const FourSensorConfig& cfg) const override;
  std::vector<std::unique_ptr<ModelEffect>> variants(const EffectContext& ctx) const override;
  double effective_trials(const EffectContext& ctx) const override;
  std::string implausibility(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  std::unique_ptr<ModelEffect> clone() const override;
  double period_mm() const { return period_mm_; }

 private:
  Eigen::MatrixXd basis(const FourSensorConfig& cfg) const;
  double period_mm_;
};

}  // namespace errsep::core

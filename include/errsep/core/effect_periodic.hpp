#pragma once
// A periodic positioning error of the slide (lead-screw pitch error, encoder interpolation error):
// δx(x) = a·cos(2πx/λ) + b·sin(2πx/λ), with the signature of effect_slide_positioning.hpp.  The
// period is searched: `variants` returns one effect per period λ₀ on a grid (4× oversampled in
// frequency, periods from 3Δx to half the travel, plus the dominant period of the residual
// spectrum), the loop keeps the best, and its p-value is corrected for the number of independent
// periods tried (`effective_trials`).  The chosen variant then refines λ = λ₀ + dperiod_mm with a
// and b in the Gauss–Newton loop (as the thermal drift refines τ): a grid period a quarter bin
// off (23.02 mm for 23 mm) drifts 0.07 rad in phase over the travel, which biased a and b by
// ~3 standard uncertainties at σ = 0.02 µm.  dperiod_mm's column vanishes at a = b = 0, so a
// candidate is scored on a and b only.
#include "errsep/core/model_effect.hpp"

namespace errsep::core {

class PeriodicEffect final : public ModelEffect {
 public:
  explicit PeriodicEffect(double period_mm = 0.0) : period_mm_(period_mm) {}
  std::string name() const override { return "periodic"; }
  std::string description() const override;
  std::string description(const Eigen::VectorXd& p) const override;
  std::vector<std::string> parameter_names() const override {
    return {"a_cos_um", "b_sin_um", "dperiod_mm"};
  }
  Eigen::MatrixXd correction_um(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  Eigen::MatrixXd jacobian(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  Eigen::MatrixXd f_shift_mm(const Eigen::VectorXd& p, const FourSensorConfig& cfg) const override;
  std::vector<std::unique_ptr<ModelEffect>> variants(const EffectContext& ctx) const override;
  double effective_trials(const EffectContext& ctx) const override;
  std::string implausibility(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  std::unique_ptr<ModelEffect> clone() const override;
  /// λ₀, the grid period of this variant (0 for the library entry).
  double period_mm() const { return period_mm_; }
  /// λ of parameters p: λ₀ + dperiod_mm, kept above half of λ₀.
  double period_mm(const Eigen::VectorXd& p) const;

 private:
  /// cos, sin and ∂δx/∂λ (µm/mm) at the positions, P × 3, for parameters p.
  Eigen::MatrixXd basis(const FourSensorConfig& cfg, const Eigen::VectorXd& p) const;
  double period_mm_;
};

}  // namespace errsep::core

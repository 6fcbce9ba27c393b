#pragma once
// First-order thermal drift of the sensor, one amplitude per configuration and one time constant
// for all of them (the sensor, its jig and the reference warm up together):
//
//   m_i(x_n) += a_i·(1 − exp(−(t_i(x_n) − t_0)/τ)),   t_0 = first reading of the scan.
//
// Non-linear in τ.  The library entry searches τ over a logarithmic grid (variants, one fixed τ₀
// each, scored with τ's column zero because it vanishes at a = 0); the chosen variant carries a
// parameter dtau_s so the Gauss–Newton loop of refine.hpp refines τ = τ₀ + dtau_s together with a.
// An onset of the warm-up before the scan started only rescales a_i (absorbed by e_i), so t_0 is
// the scan start without loss of generality.
//
// Identifiability (one scan, scan-order times t_i = i·T + x/v of the single-sensor system): with
// E(x) = exp(−x/(v·τ)) the drift is a constant per configuration (absorbed by e) plus
// b_i·E(x_n) with b_i = −a_i·exp(−i·T/τ).  Per position, S and γ absorb the part of b in
// span{1, O}; a reference surface f(x) = c·exp(−x/(v·τ)) gives f(x_n + O_i) = c·E(x_n)·E_O,i with
// E_O,i = exp(−O_i/(v·τ)), so f absorbs the part along E_O as well.  Of the four amplitudes only
// the combination of b orthogonal to span{1, O, E_O} is seen: one direction of a (for a given τ),
// plus τ itself once a ≠ 0.  Against the linear drift (effect_drift.hpp, whose one visible
// direction is x·(b ⟂ {1, O, O²})) the thermal direction stays identifiable while v·τ is not long
// against the travel; for τ much longer than a traverse E(x) ≈ 1 − x/(vτ) and the two coincide.
// Both counts are checked in tests/core/refine_effects_more.cpp.
#include "errsep/core/model_effect.hpp"

namespace errsep::core {

class ThermalDriftEffect final : public ModelEffect {
 public:
  /// tau0_s = 0: the library entry (variants search τ₀); > 0: a chosen time constant.
  explicit ThermalDriftEffect(double tau0_s = 0.0) : tau0_s_(tau0_s) {}
  std::string name() const override { return "thermal"; }
  std::string description() const override;
  std::vector<std::string> parameter_names() const override {
    return {"a1_um", "a2_um", "a3_um", "a4_um", "dtau_s"};
  }
  Eigen::MatrixXd correction_um(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  Eigen::MatrixXd jacobian(const Eigen::VectorXd& p, const EffectContext& ctx) const override;
  std::vector<std::unique_ptr<ModelEffect>> variants(const EffectContext& ctx) const override;
  double effective_trials(const EffectContext& ctx) const override;
  std::unique_ptr<ModelEffect> clone() const override;

  double tau0_s() const { return tau0_s_; }
  /// τ of parameters p (τ₀ + dtau_s, kept above a small fraction of τ₀).
  double tau_s(const Eigen::VectorXd& p) const;
  /// The τ₀ grid the library entry searches for readings taken at times t (P × 4): `count`
  /// values log-spaced from 1/30 to 2 times the scan's duration.
  static std::vector<double> tau_grid_s(const Eigen::MatrixXd& t_s, int count = 10);

 private:
  double tau0_s_;
};

}  // namespace errsep::core

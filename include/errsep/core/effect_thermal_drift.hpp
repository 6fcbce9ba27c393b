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
// plus τ itself once a ≠ 0 (relative singular value of the a direction 0.11-0.28 over the τ grid
// of a 128 s Example 1 scan).  Against the linear drift (effect_drift.hpp, one visible direction)
// the two stay separable but barely: with the linear drift in the model the thermal direction
// keeps a relative singular value of 0.07 (τ = 4 s) down to 0.004 (τ = 250 s), and the linear
// drift after the thermal one 0.1 down to 5·10⁻⁵; for τ long against a traverse E(x) ≈ 1 − x/(vτ)
// and they coincide.  Checked in tests/core/refine_effects_more.cpp.
//
// What no refinement can undo: the settled part of the drift (a_i for t ≫ τ) is a change of the
// zero-adjustment values e_i, and an e with a component quadratic in the sensor offset is what
// trades with a bow of f (four_sensor_system.hpp, CurvatureGauge).  A drift on one configuration
// alone (a = (0, 0, 3, 0) µm) can therefore put a bow into f̂ and Ŝ that only λ decides: seen
// 655 µm of S error (after the best-fit line) for τ = 25 s where the L-curve chose λ = 9·10⁻⁸,
// 0.23 µm for τ = 40 s.  The loop removes only the identifiable combination (tested with that
// part).
#include "errsep/core/model_effect.hpp"

namespace errsep::core {

class ThermalDriftEffect final : public ModelEffect {
 public:
  /// tau0_s = 0: the library entry (variants search τ₀); > 0: a chosen time constant.
  explicit ThermalDriftEffect(double tau0_s = 0.0) : tau0_s_(tau0_s) {}
  std::string name() const override { return "thermal"; }
  std::string description() const override;
  std::string description(const Eigen::VectorXd& p) const override;
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

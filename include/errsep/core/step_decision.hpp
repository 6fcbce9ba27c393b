#pragma once
// Whether a fitted correction is applied, decided on the error of what the user gets (issue 16),
// not on the residual alone.  Shared by the four-sensor refinement (refine.hpp) and the
// displacement method's (displacement_refine.hpp).
//
// A significant effect (the residual's F-test) is not yet a useful correction.  With parameters
// p̂ of covariance C and, for each reported quantity q (S, γ, f; w, m, …), its linearised
// sensitivity D_q (the change of q when the correction is applied, per unit parameter, with the
// gauge directions removed because a step never moves what the data cannot see):
//
//   applied:      q carries the parameters' error D_q(p̂ − p): added variance  diag(D_q C D_qᵀ)
//   left out:     q carries the bias of the effect D_q·p, estimated from the fitted size:
//                 E[(D_q p̂)²] = (D_q p)² + diag(D_q C D_qᵀ)
//
// Summed over the points of every quantity, each point scaled by the quantity's own standard
// uncertainty u_q (so µm of S, µrad of γ and µm of f weigh alike and a point the separation
// determines well weighs more), the expected squared error is V = Σ diag(DCDᵀ)/u² with the
// correction and B = Σ [(D p̂)² − diag(DCDᵀ)]/u² (unbiased for Σ (D p)²/u²) without it.  The
// correction is applied when V <= max_error_ratio·B (the expected squared error at least halved
// by default: at the margin both choices are as good, and a correction whose benefit is within
// its own scatter is not worth the risk of making a result worse) and no single quantity's
// expected squared error rises by more than max_quantity_increase of its own noise (an effect
// that helps f must not degrade S).  Otherwise it is reported as detected and its fitted size
// goes into the uncertainty instead: u² + (D p̂)², which covers the bias of leaving it out
// (conservatively: by its own variance).
//
// For an effect non-linear in its parameters (the reference sampled at shifted points) D is the
// linearisation at p̂, and the change the correction really makes differs from D·p̂ by a
// remainder r (QuantityImpact::remainder): neither V nor B sees it, so it is added to V, the
// expected squared error with the correction (the result carries it in u too, refine.cpp).
//
// B is estimated from the same p̂ whose significance chose the effect, so it is too large on
// average exactly when a decision is needed (winner's curse: an effect added because its fit
// came out 3–4 standard deviations from zero on noise alone has B ≈ 10 V; a poorly determined
// parameter fitted 3σ from its true value adds its error to the "bias" it removes).  With
// bias_z > 0 the decision uses the lower confidence bound B − z·sd(B) instead of B, sd(B) from
// the variance of the quadratic form p̂ᵀMp̂ (M = Σ_q D_qᵀ diag(1/u²) D_q) for p̂ ~ N(p, C):
// 4 pᵀMCMp + 2 tr(MCMC), evaluated at p̂ (which overstates it slightly: conservative).
#include <Eigen/Core>
#include <string>
#include <vector>

namespace errsep::core {

/// What a correction does to one reported quantity of n points.
struct QuantityImpact {
  std::string name;  ///< "S", "gamma", "f", "w", …
  std::string unit;  ///< "um", "urad"
  /// n × k: change of the quantity per unit of each parameter when the correction is applied
  /// (linearised), gauge directions removed.
  Eigen::MatrixXd sensitivity;
  /// n: the quantity's standard uncertainty (k = 1) without the correction.  Points with u = 0
  /// (pinned by the gauge) do not count.
  Eigen::VectorXd u_base;
  /// n or empty: what the linearised change D·p̂ misses of the change the correction at p̂
  /// really makes (an effect non-linear in its parameters).  The linearisation that sizes V and
  /// B is off by it either way, so it counts with the scatter: V += Σ r²/u² (file comment).
  Eigen::VectorXd remainder = Eigen::VectorXd();
};

struct StepDecisionOptions {
  /// Apply when the expected (u-weighted) squared error with the correction is at most this
  /// fraction of the one without it.
  double max_error_ratio = 0.5;
  /// … and no quantity's expected squared error grows by more than this fraction of its own
  /// noise (Σ u² over its points).
  double max_quantity_increase = 0.1;
  /// Decide on B − bias_z·sd(B), a lower confidence bound of the bias removed (file comment).
  /// 0: on B itself.
  double bias_z = 0.0;
  bool is_valid(std::string* why = nullptr) const;
};

/// One quantity's figures of a decision (RMS over its points, in the quantity's unit).
struct QuantityEffect {
  std::string name, unit;
  double rms_u_base = 0;   ///< of the separation alone
  double rms_change = 0;   ///< of D·p̂: what applying the correction changes
  double rms_added_u = 0;  ///< sqrt(mean(diag(DCDᵀ) + r²)): what applying adds to u (quadrature)
  /// sqrt(max(0, mean((D p̂)² − diag(DCDᵀ)))): estimated RMS bias of leaving the effect out.
  double rms_bias = 0;
  /// Expected mean squared error with the correction over without it, per point in u² units:
  /// (n + Σ var/u²)/(n + Σ bias²/u²).
  double expected_mse_ratio = 1;
};

struct StepDecision {
  bool apply = false;
  double variance_sum = 0;  ///< V of the file comment
  double bias_sum = 0;      ///< B of the file comment (may be negative: no detectable bias)
  double bias_sd = 0;       ///< sd(B) (file comment)
  /// What the decision compared V with: B − bias_z·sd(B).
  double bias_bound = 0;
  std::vector<QuantityEffect> quantities;
  std::string reason;  ///< why (one line)
  /// The quantity's effect by name (nullptr when absent).
  const QuantityEffect* quantity(const std::string& name) const;
};

/// Decides for parameters p (k) with covariance C (k × k).  Throws std::invalid_argument for
/// inconsistent sizes.
StepDecision decide_step(const Eigen::VectorXd& p, const Eigen::MatrixXd& cov,
                         const std::vector<QuantityImpact>& quantities,
                         const StepDecisionOptions& opts = {});

/// The standard uncertainty of a quantity once every effect is decided: u_sep (the separation of
/// the readings corrected for the applied effects) with, in quadrature, the applied parameters'
/// covariance carried through the sensitivities (diag(D_A C_AA D_Aᵀ)) and, for the parameters
/// left out, the square of what they would have changed ((D_L p̂_L)², the bias of leaving them
/// out).  D is n × K over all parameters, C K × K, `applied` K entries.
Eigen::VectorXd refined_uncertainty(const Eigen::VectorXd& u_sep, const Eigen::MatrixXd& D,
                                    const Eigen::MatrixXd& cov, const Eigen::VectorXd& p,
                                    const std::vector<bool>& applied);

/// Upper-tail p-value of an F statistic with (k, dof) degrees of freedom: the significance of k
/// columns added to a least-squares fit that leaves dof.  1 when k, dof or F is not positive.
double f_test_p_value(double F, int k, int dof);

/// One line for a report, e.g. "gain detected (g3 = 0.023 +- 0.055): not applied, adds 0.41 um
/// to u_S (rms, in quadrature)" or "pe1 applied (dD2_mm = …): S changed by 0.8 um rms, u_S +0.02".
std::string describe_decision(const std::string& effect, const std::vector<std::string>& names,
                              const Eigen::VectorXd& p, const Eigen::VectorXd& u_p,
                              const StepDecision& d);

}  // namespace errsep::core

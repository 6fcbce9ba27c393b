#pragma once
// Separation and refinement of a four-sensor scan measured with a scan sequence
// (scan_sequence.hpp; issue 16, items 2 and 3): the redundant traverses enter the least-squares
// system of Eq. (1) (Zhao et al. 2019) as extra rows, each with its own zero-adjustment unknown,
// and the refinement identifies the time-dependent effects the redundancy makes visible.
//
// The fit.  Unknowns: f(x_0..x_{N−1}) in the gauge f(x_0) = f(x_{N−1}) = 0, f ⟂ bow (as the
// refine base and the solver's default), S(x_n) and γ(x_n) per position, a zero adjustment e_k
// per traverse (traverse 1 and the first traverse of configuration 4 held at 0: the constant and
// γ's constant; a repeated configuration shares its first traverse's e when
// ScanSequence::repeat_keeps_zero).  Ordinary least squares (λ = 0) because only an
// unregularised fit has a residual whose distribution is known.  u_S is the standard uncertainty
// of Ŝ about its best-fit constant, line and bow (what one scan cannot see is removed from the
// estimate and the truth alike), from σ̂ and the covariance of the joint fit, so the effects'
// fitted directions are carried in it.
//
// The effects, in reading space (the physics of effect_drift.hpp, effect_thermal_drift.hpp and a
// progressive form of effect_traverse.hpp):
//   drift     a_c·t per configuration c (4 rates)
//   thermal   A_c·(1 − exp(−t/τ)) per configuration, τ searched on ThermalDriftEffect's grid
//   traverse  s_k·Σ_j b_j·P_j(2x/L − 1), j = 1..K: a straightness that changes in proportion to
//             time, s_k = (mid-time of traverse k − that of traverse 1)/(span of mid-times); the
//             truth is the first traverse's S
// A candidate's columns are projected onto the complement of the current model; directions with
// a relative singular value above the tolerance are identifiable, and the F-test on them
// (Šidák-corrected over τ's grid, Bonferroni over the candidates) decides whether it is added.
// Only an effect the plan identifies (below) is added; a significant one it does not is
// reported.  When another significant candidate explains the chosen one's signal (the chosen is
// no longer significant with the other in the model) the two are reported as not separable from
// the plan and neither is applied (a drift leaves S alone, a non-repeating S is a change of S:
// applying the wrong one moves S).  Linear and thermal drift are one family (a·t is the long-τ
// limit of A·(1 − exp(−t/τ))), not rivals.
//
// Identifiability from the plan (independent of the data): the directions of an effect's
// parameters that the data cannot see, or see too weakly to fit (relative singular value of the
// projected, unit-scaled columns below weak_direction_sv), are absorbed by f, S, γ, e.  When
// such a direction changes S beyond the gauge (constant, line, bow), the effect is "not
// identifiable from this plan": no fitted correction can remove what it does to S.  The measure
// (undetermined_S_gain) is the largest ratio, over those directions, of the RMS change of Ŝ
// (after the gauge) to the RMS of the effect in the readings.  Measured on Zhao 2019's geometry
// (N = 69, s = 1, 1, 5, 10 mm/s, 2 s turnaround): single plan drift 4.9, thermal 2.9, traverse
// 7.1 (all weakly determined); closing pass drift 2.2, thermal 0.89, traverse 0; reversed drift
// 0, thermal 0.06, traverse 0; interleaved drift 1.2, thermal 0.73, traverse 0.  The threshold
// undetermined_S_max = 0.1 separates them.
//
// An effect detected (significant on the directions the data see) that the plan cannot identify
// is not applied, and u_S is widened by what it could do to S (issue 16 item 1: "widen the
// uncertainty instead of applying it").  Its fitted coefficients along the directions the data
// determine, each at its size plus its standard uncertainty ((|uⱼᵀr| + σ̂)/svⱼ), give (a) the S
// change of that visible part, which the unrefined fit keeps, and (b) a per-direction size s²
// (their mean) taken for each undetermined direction, whose S change the data cannot bound
// otherwise:
//   u_add(x)² = (toS·V_seen·c)(x)² + s²·Σ_undetermined (toS·v_j)(x)²,
// toS being what the fit puts into Ŝ (after the gauge) from readings along the effect's columns.
// Each effect's own u_add is reported (u_S_added_um); u_S is widened once, by the same formula
// applied to all detected effects' columns side by side (their joint seen and undetermined
// directions), because they are often the same signal (a drift and a warm-up of the single
// plan): u_S = sqrt(u_S² + u_add,joint²).
//
// The drift family.  A thermal drift added at a grid τ gets τ fitted (golden section between the
// grid's neighbours) and carried in u_S by its Gauss-Newton column Σ_c Â_c·∂J_c/∂τ.  A linear
// drift (the τ → ∞ limit of a warm-up) and a warm-up often fit the readings almost equally well
// yet give different S (what differs, a configuration's curvature in time against its slope, is
// mostly absorbed by S, γ, e).  The form is decided on evidence (drift_form_decision): both are
// fitted, the thermal one with τ fitted, and the thermal one is taken only when τ beats the line
// on the F-test Šidák-adjusted over the τ grid; otherwise, where their S differ by more than a
// tenth of u_S, S is taken midway, half the difference enters u_S (or τ's 95 % profile set
// about the midway S where it reaches farther: u_S_drift_form_um) and the report says "drift
// form not identifiable from this plan".  A thermal form taken enters u_S with its profile set
// (linear member and 40 τ, 95 % bound) at half the largest S difference.

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "errsep/core/four_sensor_config.hpp"
#include "errsep/core/iso230.hpp"
#include "errsep/core/repeat_steps.hpp"
#include "errsep/core/residual_trace.hpp"
#include "errsep/core/scan_sequence.hpp"
#include "errsep/core/step_decision.hpp"

namespace errsep::core {

enum class SequenceEffectKind { drift, thermal, traverse };
const char* to_string(SequenceEffectKind k);

struct SequenceFit {
  Eigen::VectorXd f_um, S_um, gamma_rad;  ///< N, P, P
  Eigen::VectorXd e_um;                   ///< T zero-adjustment values, one per traverse
  Eigen::VectorXd u_S_um;  ///< of S about its best-fit constant, line and bow (k = 1)
  /// G (P × k): Cov(Ŝ) = G·Gᵀ in the fit's own gauge (f(x_0) = f(x_{N−1}) = 0, f ⟂ bow, e of
  /// traverse 1 and configuration 4 held at 0), the bow of S included: what an ISO 230-1
  /// straightness of Ŝ needs (sequence_straightness).  After a refine it also holds the
  /// widening's columns (SequenceRefineResult::u_S_widening_um).
  Eigen::MatrixXd S_covariance_factor_um;
  /// Of γ about its best-fit constant and line (k = 1), as u_S_um is about S's constant, line
  /// and bow: what one scan's readings see of γ (the constant is set only by e_4 = 0, Eq. 19, and
  /// a fitted warm-up of configuration 4 moves it; the and the sweep's measure).
  Eigen::VectorXd u_gamma_rad;
  /// G (P × k): Cov(γ̂) = G·Gᵀ in the fit's gauge (the constant that e_4 = 0 sets included), as
  /// S_covariance_factor_um for S; after a refine it holds the hysteresis's terms too.  What a
  /// figure of γ that cancels its constant (the angular deviation, max − min) needs when a fitted
  /// warm-up of configuration 4 leaves that constant all but undetermined.
  Eigen::MatrixXd gamma_covariance_factor_rad;
  /// Of f in the fit's gauge (its ends at 0), k = 1.
  Eigen::VectorXd u_f_um;
  /// The row norms of S_covariance_factor_um: u(Ŝ) in the fit's gauge, the bow included.
  Eigen::VectorXd u_S_in_gauge_um() const { return S_covariance_factor_um.rowwise().norm(); }
  /// The row norms of gamma_covariance_factor_rad: u(γ̂) in the fit's gauge, what a result that
  /// states γ in that gauge carries (motion.csv).
  Eigen::VectorXd u_gamma_in_gauge_rad() const {
    return gamma_covariance_factor_rad.rowwise().norm();
  }
  Eigen::VectorXd extra_coefficients;  ///< along the extra columns
  Eigen::MatrixXd residual_um;         ///< P × T
  double rss_um2 = 0, sigma_um = 0;
  int dof = 0;
};

/// The fit of the file comment with extra reading-space columns (PT × q, row k·P + n; may be
/// empty).  Throws std::invalid_argument for a bad configuration, sequence or shape.
SequenceFit fit_four_sensor_sequence(const FourSensorConfig& cfg, const ScanSequence& seq,
                                     const Eigen::MatrixXd& m_um,
                                     const Eigen::MatrixXd& extra = {});

/// The ISO 230-1 straightness of fit.S_um about `reference` with its U (k = 2) from the fit's
/// covariance (S_covariance_factor_um; the bias by `draws` Monte-Carlo draws, seeded): as
/// four_sensor_straightness for a single scan.  Throws std::invalid_argument as
/// estimate_straightness.
StraightnessEstimate sequence_straightness(const SequenceFit& fit, const Eigen::VectorXd& x_mm,
                                           ReferenceLine reference, int draws = 100);

/// The ISO 230-1 angular deviation of fit.gamma_rad (max − min) with its u from the fit's
/// covariance (gamma_covariance_factor_rad, correlations included: u_uncorrelated = u_bound =
/// the exact u, so either Correlation gives it): max − min cancels γ's constant, which the
/// pointwise propagation of the gauge's u(γ̂) cannot (a fitted warm-up of configuration 4: U
/// thousands of µrad against a γ error of ~10 µrad).  Throws std::invalid_argument as
/// evaluate_angular_deviation, or when the factor's rows differ from γ's length.
AngularResult sequence_angular_deviation(const SequenceFit& fit,
                                         const EvaluationOptions& opts = {});

/// An effect's columns for a sequence (rows k·P + n), at time constant tau_s for thermal.
struct SequenceEffectColumns {
  SequenceEffectKind kind = SequenceEffectKind::drift;
  std::string description;
  Eigen::MatrixXd J;
};
SequenceEffectColumns sequence_effect_columns(SequenceEffectKind kind, const FourSensorConfig& cfg,
                                              const ScanSequence& seq, double tau_s = 40.0,
                                              int traverse_degree = 4);

struct SequenceIdentifiability {
  SequenceEffectKind kind = SequenceEffectKind::drift;
  int parameters = 0;
  int identifiable = 0;  ///< directions above identifiability_tol
  /// Directions above weak_direction_sv.  An effect the plan identifies is fitted on all its
  /// identifiable directions (the weak ones do not reach S, by the plan's measure); one it does
  /// not would be scored on these only.
  int strong = 0;
  Eigen::VectorXd relative_sv;
  double undetermined_S_gain = 0;  ///< file comment (µm of S RMS per µm of reading RMS)
  bool identifiable_from_plan = false;
  /// Thermal drift only (0 for the other kinds): the same gain for its columns beyond a linear
  /// drift's, at the τ grid's middle: what S may take from a warm-up that the plan cannot tell
  /// from a line, the form drift_form_decision weighs.  A ranking, not a verdict: the reversed
  /// plan 0.63, reversed closing 0.13 on the paper's geometry, and the refine tells the forms
  /// apart on the latter (scan_sequence.hpp).
  double form_undetermined_S_gain = 0;
};

struct SequenceRefineOptions {
  double alpha = 0.01;                ///< family-wise level of one step
  int max_effects = 2;                ///< additions at most
  double identifiability_tol = 1e-6;  ///< relative singular value below which a direction is lost
  /// A direction whose relative singular value is below this is too poorly determined to fit
  /// (its noise would go into S); it counts as undetermined.  0.05: the single plan's
  /// non-repeating traverse has 0.013-0.035 (not identifiable), the closing pass's 0.51-0.56.
  double weak_direction_sv = 0.05;
  /// An effect is not identifiable from the plan above this undetermined_S_gain.
  double undetermined_S_max = 0.1;
  int thermal_grid = 10;    ///< τ values searched (ThermalDriftEffect::tau_grid_s)
  int traverse_degree = 4;  ///< K of the progressive traverse change
  /// Search the differences of repeated traverses for a knocked sensor first (repeat_steps.hpp)
  /// and, when one is attributed, fit its step before the effects (SequenceKnock).
  bool find_knocks = true;
  /// The drift family's form decided on evidence (sequence_refine.cpp): the linear member and the
  /// thermal one with τ fitted are both fitted; the thermal one is taken only when τ beats the
  /// line on the F-test Šidák-adjusted over the τ grid; otherwise, where the two forms' S differ
  /// by more than a tenth of u_S, S is taken midway between them, half the difference (or τ's
  /// profile set) carried in u_S, and the report says "drift form not identifiable from this
  /// plan".  Measured (reversed plan, seeds 1001-1020, σ 0.1): a line taken for a warm-up at
  /// τ 34 s (seed 1003, all configurations) 0.09 -> 1.90 um with u_S 0.65 um without it.  Off:
  /// the behaviour before it (a thermal member the first round chose is kept; a line is replaced
  /// on the unadjusted test, or the adjusted one with prefer_linear_drift).
  bool drift_form_decision = true;
  /// Each effect the F-test chooses is taken into the fit only when decide_step
  /// (step_decision.hpp) expects S, γ and f to improve (the sensitivities: what the model before
  /// the step puts into them from the effect's columns; the parameters and their covariance: the
  /// model with them), or when it changes none of them by a tenth of their u (a linear drift of a
  /// plan that reads every configuration both ways: taken so that σ̂ is the noise's).  Otherwise
  /// the effect is reported as detected and not applied (SequenceRefineResult::declined) and
  /// u_S carries its bias (D_S·p̂)².  Off: every chosen effect is applied (the F-test alone).
  bool decide_steps = true;
  /// The rule of those decisions: the lower confidence bound of the bias (bias_z = 2), as the
  /// single-scan refine's (refine_step_decision()): an effect chosen because it scored highest on
  /// the same readings has its bias overestimated (step_decision.hpp).
  StepDecisionOptions decision = [] {
    StepDecisionOptions d;
    d.bias_z = 2.0;
    return d;
  }();
  /// The lower bound (decision.bias_z) guards against the winner's curse: a step chosen because
  /// its fit came out far from zero on the same readings has its bias overestimated.  When the
  /// F-test's p-value is below this fraction of the threshold it passed (α over the candidates),
  /// the effect would have been chosen on almost any draw of the noise, the selection does not
  /// bias p̂, and the step is decided on B itself (bias_z = 0).  Measured (reversed plan, seeds
  /// 1001-1020): a real non-repeating traverse at σ 0.2 has p 1e-7-1e-10 and B − 2 sd(B) < 2V
  /// (declined in 12 of 20 runs with the bound); the spurious one of seed 1046 has p 0.002
  /// against a threshold of 0.0033.
  double certain_selection_ratio = 0.01;
  /// The drift family's simpler member first: when the linear drift is significant too, it is
  /// the step taken, and the thermal form replaces it only when its τ beats the line on the
  /// F-test Šidák-adjusted over the τ grid (τ exists only under the thermal form: the best τ of
  /// a search beats the line by chance far more often than the 1-dof test says).  A linear
  /// drift of a reversed plan leaves S alone; taken for a warm-up at τ 34 s (seed 1003, all
  /// configurations, σ 0.1) it moved S 0.09 -> 1.90 um with u_S 0.65, which this option fixes.
  /// Off by default because it costs more than it fixes (seeds 1001-1020, reversed plan): the
  /// thermal_all cells halved 10 -> 8 of 19 (σ 0.1), 17 -> 12 of 20 (0.05), 8 -> 6 of 14 (0.2),
  /// the line taken first is then often ambiguous with a non-repeating traverse (nothing
  /// applied), one run reached 13 um with a u_S as large, and a knock run ended beyond 4 u_S.
  /// Off: the better-scoring member, switched to the thermal one on the unadjusted test.
  bool prefer_linear_drift = false;
  RepeatStepOptions repeat_steps;
  /// Test the sensor's hysteresis on plans that read a configuration both ways and take it into
  /// the fit when decide_step expects S, γ, f to improve (SequenceHysteresis).
  bool fit_hysteresis = true;
  /// Where the fitted slope leaves a reading's lag sign uncertain (the profile turns), weigh it
  /// by the reading itself too: the two signs differ by 2h in that reading, h ≫ σ in the cases
  /// that matter (SequenceRefine's refine_hysteresis).  Off: the slope's sign alone.
  bool hysteresis_signs_from_readings = true;
  /// A declined effect's bias carried in u_S is held where its fitted change of the readings
  /// exceeds this many times what the sensors read at all (RMS about each traverse's mean), and
  /// SequenceRefineResult::unbounded says u_S is unbounded: the single-scan refine's rule
  /// (RefineOptions::reading_bound).  0: no bound.
  double reading_bound = 3.0;
  bool is_valid(std::string* why = nullptr) const;
};

/// A knocked sensor that the plan's repeated traverses name (repeat_steps.hpp), in the fit.
/// The physics: the one sensor of the single-sensor system is knocked during traverse K between
/// two positions; from there on (in K's direction of travel) traverse K and every later traverse
/// read offset by the knock's size.  Its column in the fit is exactly that; on a traverse with its
/// own zero adjustment the later constant is absorbed, the step within K is not.  The difference
/// of a configuration's two traverses shows the step but not which of the two held it; the fit
/// tells them apart only through the few positions a single scan sees a step at (gross_errors
/// .hpp), so both are fitted and the better taken; when their residuals differ by less than
/// attribution_chi2·σ̂² the difference of their S enters u_S as |ΔS|/√2 (the RMS error of taking
/// one of two equally likely alternatives).  Removed when decide_step (step_decision.hpp) expects
/// S, γ and f to improve; else the fit stays without it and u_S carries its bias (D_S·p̂)².
struct SequenceKnock {
  RepeatStepScan scan;   ///< the search; scan.found && scan.attributed: a knock named
  bool fitted = false;   ///< its column was fitted (a knock named)
  bool applied = false;  ///< removed from the result (decide_step); else carried in u_S
  int traverse = -1;     ///< 0-based: the traverse the knock fell in (the better fitting)
  bool traverse_ambiguous = false;    ///< the other of the pair fits within attribution_chi2
  double size_um = 0, u_size_um = 0;  ///< fitted in the sequence model (no effects)
  double x_mm = 0;                    ///< where (the first position the step holds)
  std::string decision;               ///< decide_step's reason
  /// P: what the knock adds to u_S (traverse ambiguity; when not applied, its bias); zeros when
  /// none.
  Eigen::VectorXd u_S_added_um;
  std::string finding;  ///< one line (also in SequenceRefineResult::report); empty when none
};

struct SequenceCandidate {
  SequenceEffectKind kind = SequenceEffectKind::drift;
  std::string description;
  int identifiable = 0;
  double F = 0, p_value = 1, delta_rss_um2 = 0;
  /// thermal: the time constant of the best score on the grid; once added, the least-squares τ
  /// (searched between the grid's neighbours), with its standard uncertainty u_tau_s.
  double tau_s = 0;
  double u_tau_s = 0;
  /// Detected but not identifiable: the RMS over x of what it adds to u_S (widen_u_S_um);
  /// declined by the step decision: the RMS of its bias D_S·p̂ carried in u_S.
  double u_S_added_um = 0;
  /// decide_step's reason when the step was decided (SequenceRefineOptions::decide_steps).
  std::string decision;
};

/// A sensor non-linearity m = u + c₂·(u − mid)² (u the linear reading; not in the effect
/// library).  On one pass per configuration most of c₂·(u − mid)² is absorbed by f, S, γ and e,
/// and only the trace's reading-level test (residual_trace.hpp) can find it: reported, not
/// corrected.  A plan that reads configurations again with the sensor re-zeroed by Δ
/// (ScanSequence::rezeroed) adds the difference 2·c₂·Δ·(u − mid) + const between the passes,
/// which none of them absorbs, so c₂ is determined: the refine first fits the base model with
/// the column (û − mid)² at the base fit's fitted readings û (one Gauss–Newton step from c₂ = 0;
/// iterating it at the fit's linear part was tried and made S worse), and when its F test is
/// significant keeps the column in the base design for the knock search and the effects, c₂
/// carried in u_S by the joint fit.  Measured (tests/core/sequence_refine, 50σ·(2-4 %) of the
/// half range, Δ = the first pass's range, 20 random profiles per σ 0.05/0.1/0.2): found 60/60,
/// S error halved in 47 of the 51 runs where it doubled it, never worse, coverage 0.978.
struct SequenceNonlinearity {
  /// Rezeroed plan: the column's F test in the base fit; else the trace's quadratic test.
  bool detected = false;
  bool identifiable = false;  ///< the plan re-zeroes (ScanSequence::rezeroed)
  bool applied = false;       ///< the result is the fit with c₂
  double c2_per_um = 0, u_c2_per_um = 0, mid_um = 0;
  double F = 0, p_value = 1;  ///< of the c₂ column in the sequence fit
  std::string finding;        ///< one line when detected, else empty
};

/// The sequence fit with the non-linearity column of SequenceNonlinearity at before's fitted
/// readings; the figures go to `nl`.  `alpha`: the F test's level.  Throws as
/// fit_four_sensor_sequence.
SequenceFit fit_sequence_nonlinearity(const FourSensorConfig& cfg, const ScanSequence& seq,
                                      const Eigen::MatrixXd& m_um, const SequenceFit& before,
                                      SequenceNonlinearity* nl, double alpha = 0.01);

/// A hysteresis of the sensor: it reads r − h·sign(dr/dt), lagging behind the surface by h in the
/// direction its reading changes (backlash of its plunger, friction of its tip).  With the slide
/// at ±v, dr/dt = ±v·dr/dx: a reading offset that depends on the direction of travel and on the
/// sign of the profile's slope, column −(direction)·sign(dû/dx) at the fitted readings û (one
/// Gauss–Newton step from h = 0, as the non-linearity's).  One h for the sensor, not one per
/// configuration: the sequence is read by the one sensor of the single-sensor system, moved
/// between configurations, and its lag is the sensor's; one parameter is determined by any
/// configuration read both ways and corrects the configurations read one way only, where four
/// would each need their own reversal.  Identifiable only when some configuration is read
/// forward and backward (its two traverses read the same points, so the column's flip between
/// them is absorbed by none of f, S, γ, e); read one way only, a lag is part of the profile read
/// and the plan cannot tell them apart ("not identifiable from this plan").  Detected by the
/// column's F test in the base fit; taken into the fit (its coefficient's covariance in u_S by
/// the joint fit) when decide_step (step_decision.hpp) expects S, γ, f to improve, or when it
/// changes none of them (a plan that reads every configuration both ways averages it out of the
/// estimates, but its residual would inflate σ̂); else left out with its bias (D_S·ĥ)² in u_S.
struct SequenceHysteresis {
  bool identifiable = false;  ///< some configuration is read both ways
  bool detected = false;      ///< its column's F test in the base fit
  bool applied = false;       ///< taken into the result's fit
  double h_um = 0, u_h_um = 0;
  double F = 0, p_value = 1;
  std::string decision;  ///< decide_step's reason (or why it was taken in without changing S)
  /// P: what it adds to u_S when detected: its bias when not applied; when applied, the spread
  /// of its sign at the profile's turns (the sign's variance and the two sign rules' half
  /// difference); zeros otherwise.
  Eigen::VectorXd u_S_added_um;
  /// Applied with the readings weighing the signs: the RMS of the difference in S between that
  /// fit and the fit with the slope's sign alone (half of it is carried in u_S and u_γ); 0
  /// otherwise.
  double sign_rules_dS_rms_um = 0;
  /// One line when detected (also in SequenceRefineResult::report), or, on a plan that reads
  /// every configuration one way only, "hysteresis: not identifiable from this plan (...)" (not
  /// in the report: a clean run says nothing).
  std::string finding;
};

struct SequenceRefineResult {
  std::string plan;                            ///< "single", "closing pass", … or "custom"
  SequenceFit before, after;                   ///< without effects; with the added ones
  std::vector<SequenceCandidate> added;        ///< in order
  std::vector<SequenceCandidate> first_round;  ///< every candidate's score in round 1
  /// Significant, but the plan cannot identify them: not added, reported, and `after.u_S_um`
  /// widened by what each could do to S (file comment).
  std::vector<SequenceCandidate> detected_not_identifiable;
  /// Identifiable and significant, but the step decision expects it to make S, γ or f worse (too
  /// poorly determined, with the model it would join, to remove more error than it adds): not
  /// applied, reported, its bias carried in u_S (u_S_declined_um).
  std::vector<SequenceCandidate> declined;
  /// P: the part of after.u_S_um that the declined effects' bias adds (quadrature); zero when none.
  Eigen::VectorXd u_S_declined_um;
  /// One line per term of u_S held at the readings' bound (SequenceRefineOptions::reading_bound),
  /// "u_S unbounded: <effect> not determined by this plan; declare a bound (...)", as
  /// RefineResult::unbounded; also in `report`.  Empty: every term is bounded by the data.
  std::vector<std::string> unbounded;
  /// P: the part of after.u_S_um that the detected-but-unidentifiable effects add (quadrature);
  /// zero when there are none.
  Eigen::VectorXd u_S_widening_um;
  /// P: the part of after.u_S_um that the drift's form adds: when the data do not tell a linear
  /// drift from a thermal one, |ΔS|/2 (ΔS the difference of Ŝ between them; Ŝ midway), or half
  /// the largest S change over τ's 95 % profile set where it reaches farther; zero otherwise.
  Eigen::VectorXd u_S_drift_form_um;
  /// Significant candidates the data cannot tell apart (one explains the other's signal): not
  /// applied; one line each, also in `report`.
  std::vector<std::string> ambiguous;
  std::vector<SequenceIdentifiability> plan_identifiability;  ///< drift, thermal, traverse
  /// A knocked sensor named by the repeated traverses, fitted before the effects.
  SequenceKnock knock;
  /// A sensor non-linearity the trace found; corrected when the plan re-zeroes.
  SequenceNonlinearity nonlinearity;
  /// The sensor's hysteresis, tested on plans that read a configuration both ways.
  SequenceHysteresis hysteresis;
  /// The residual of every traverse under the final fit traced against time, position, reading
  /// level and direction (trace_sequence_residual); its findings are also in `report`.
  ResidualTrace trace;
  /// One line per added effect and one per effect detected that this plan cannot identify, e.g.
  /// "drift: not identifiable from this plan (single): ...".  The report prints them.  An effect
  /// the plan cannot identify and the data do not suggest gets no line (a clean run says nothing).
  std::vector<std::string> report;
  bool identified(SequenceEffectKind k) const;
  bool identifiable_from_plan(SequenceEffectKind k) const;
};

/// Data-independent: what the plan lets each effect show (file comment).
std::vector<SequenceIdentifiability> sequence_identifiability(const FourSensorConfig& cfg,
                                                              const ScanSequence& seq,
                                                              const SequenceRefineOptions& o = {});

/// The loop on readings m (P × T, column k = traverse k).  Throws std::invalid_argument for bad
/// inputs.  One call builds a SequenceModel and discards it; to refine several scans of one plan,
/// keep the model.
SequenceRefineResult refine_four_sensor_sequence(const FourSensorConfig& cfg,
                                                 const ScanSequence& seq,
                                                 const Eigen::MatrixXd& m_um,
                                                 const SequenceRefineOptions& o = {});

/// The plan's side of the fit and the refine: everything that depends on the configuration, the
/// sequence (its reading times included) and the options, never on the readings: the base design,
/// the candidates' columns (drift, thermal at each τ of the grid, traverse), the factorisation of
/// every column set the refine meets (the base, then the base with each added effect), the
/// projections and the identifiability.  Built once, it makes each later fit or refine of a scan
/// of the same plan a few matrix-vector products (a refine of the reversed plan: ~30 ms rebuilt
/// per call, ~2 ms with the model kept).  refine() fills its caches as it meets new column sets:
/// not thread-safe; one model per thread.  Results equal those of the free functions.
class SequenceModel {
 public:
  /// Throws std::invalid_argument for a bad configuration, sequence or options.
  SequenceModel(const FourSensorConfig& cfg, const ScanSequence& seq,
                const SequenceRefineOptions& o = {});
  ~SequenceModel();
  SequenceModel(SequenceModel&&) noexcept;
  SequenceModel& operator=(SequenceModel&&) noexcept;
  SequenceModel(const SequenceModel&) = delete;
  SequenceModel& operator=(const SequenceModel&) = delete;

  /// fit_four_sensor_sequence without extra columns.
  SequenceFit fit(const Eigen::MatrixXd& m_um) const;
  /// refine_four_sensor_sequence.
  SequenceRefineResult refine(const Eigen::MatrixXd& m_um);
  /// sequence_identifiability.
  const std::vector<SequenceIdentifiability>& identifiability() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace errsep::core

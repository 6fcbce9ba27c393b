#pragma once
// Closing the loop on the four-sensor model (Zhao et al. 2019, Eq. 1): fit the base model, look
// at what it leaves unexplained, score every candidate effect of the library on that residual, add
// the most significant one, re-solve, and stop when nothing is significant.
//
// Fitting.  Inside the loop the base model is the ordinary least-squares fit (λ = 0, whitened
// rows: the BLUE for white sensor noise, gauge f(x_0) = f(x_{N−1}) = 0, f ⟂ bow), because only an
// unregularised fit has a residual whose distribution is known.  Effects enter as corrections of
// the readings (model_effect.hpp); PE1, PE2 and the periodic error move the point where f is
// sampled, and for them the fit samples f there through its cubic spline (exact, linear in f).
// Their parameters p are found by Gauss–Newton with f, S, γ, e eliminated (variable projection):
// the residual of that exact fit is the objective, the effects' Jacobians at its f̂, Ŝ, γ̂ give
// the step, and a step is taken only if it lowers the residual.  When an effect joins others,
// the joint re-solve also starts from zero for all of them and keeps the better end (an effect
// added alone may have absorbed the signature of one still missing).
//
// Scoring.  A candidate's columns are projected onto the complement of everything the model
// already has (base unknowns and the effects added so far); directions that vanish there are not
// identifiable (e.g. a gain common to all configurations, a drift common to all of them) and do
// not count.  With k identifiable directions, F = (ΔRSS/k)/(RSS₁/(dof − k)) is compared with
// F(k, dof − k); an effect searched over a structural choice (a period) has its best p-value
// corrected for the number of independent choices (Šidák), and the step's threshold is α divided
// by the number of candidates scored (Bonferroni), so on clean data the whole loop adds an effect
// with probability of about α.
//
// Reporting.  Every step carries the effect, its parameters with standard uncertainties (k = 1,
// from σ̂ of the augmented model; for a parameter set with non-identifiable directions the
// estimate with no component along them, i.e. in the span of the combinations the data
// determine, and the covariance of that estimate), the residual RMS before and after, the
// whiteness of the residual after it, and, when the truth is known, the error of S, γ and f
// before and after (separations with the caller's solver options on raw and corrected readings).
#include <Eigen/Core>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/gross_errors.hpp"
#include "errsep/core/model_effect.hpp"
#include "errsep/core/residual_analysis.hpp"
#include "errsep/core/residual_trace.hpp"
#include "errsep/core/sensor_nonlinearity.hpp"
#include "errsep/core/step_decision.hpp"

namespace errsep::core {

/// The refine's step decision: bias_z = 2, the lower confidence bound of the bias a correction
/// removes (step_decision.hpp), because the effect was chosen for the size of the same fit that
/// estimates that bias.  Without it a noise fit 3-4 sd from zero (clean data) or a poorly
/// determined parameter fitted 3 sd from its value (PE1's dD4) was applied and made gamma worse
/// beyond its stated u (errsep-refine-sweep, seeds 1-20; refine.cpp has the figures).
StepDecisionOptions refine_step_decision();

/// A bound the user declares on an effect of the library (a specification, e.g. a sensor's drift
/// of at most 0.03 µm/s): every parameter of `effect` lies within ±bound, in its parameter units
/// (drift µm/s, thermal µm, traverse µm, gain 1, pe1/pe2/periodic as named).  It is a Type B
/// term (GUM 4.3.7: rectangular, variance bound²/3 per parameter) for what the scan's plan cannot
/// determine of that effect: one scan absorbs most of a drift, a thermal drift on every
/// configuration or a non-repeating traverse into f, S, γ and e, and no residual can show it.
struct DeclaredEffectBound {
  std::string effect;  ///< ModelEffect::name(): drift, thermal, traverse, gain, pe1, pe2, periodic
  double bound = 0;    ///< half-width, parameter units, > 0
};

struct RefineOptions {
  FourSensorOptions solve;               ///< for the reported separations (before and after)
  ResidualAnalysisOptions residual;      ///< whiteness test of each step's residual
  double alpha = 0.01;                   ///< family-wise significance of one step
  int max_effects = 4;                   ///< stop after this many additions
  int max_gauss_newton = 12;             ///< iterations per re-solve
  double gauss_newton_tolerance = 1e-4;  ///< stop when every |Δp_j| < tolerance·u(p_j)
  double identifiability_tol = 1e-6;  ///< relative singular value below which a direction is lost
  /// A parameter direction stays in the corrected model only when its signal exceeds this many σ̂
  /// (a barely determined direction would carry its large uncertainty into S, γ and f).
  double direction_threshold = 0.0;
  double speed_mm_per_s = 10.0;  ///< for scan-order times when none were recorded
  /// P × 4: the direction of each reading (+1 forward, −1 backward) as recorded, for the residual
  /// trace (residual_trace.hpp RecordedVariables::direction); empty: not recorded.
  Eigen::MatrixXd recorded_direction;
  /// Whether a significant effect's correction is applied (step_decision.hpp): on the expected
  /// error of S, γ and f, not on the F-test alone.
  StepDecisionOptions decision = refine_step_decision();
  /// Whether the determined part of an effect is applied when the rest of it, which this plan
  /// cannot determine, could move S by more than a tenth of u_S ("not identifiable from this
  /// plan", RefineStep::undetermined_S_um).  Off: such an effect is reported and carried in u, not
  /// applied, because its correction is then judged on a part of the effect only (errsep-refine-
  /// sweep: a thermal drift of one configuration, single plan, S 0.64 -> 2.16 um, u_S 0.95).
  bool apply_unidentifiable = false;
  /// Whether a correction is applied only when effect_identifiability (below) says the plan lets
  /// it halve the errors of S and γ (the effect refitted alone to the raw readings, at its fit
  /// and linearised about zero), on top of the decision.  Off by default: it stopped PE2 at
  /// σ = 0.2 µm, seed 15 of errsep-refine-sweep (c2 = 3094 ± 540 µm for a true 795 at the global
  /// least-squares minimum, V/B = 0.015 while the plan predicts S 1.16 -> 0.67 µm: applied, S
  /// 0.48 -> 4.0 µm, γ 30 -> 224 µrad, beyond u; the decision now declines it itself, counting
  /// what the correction's linearisation misses), but it also stops corrections that help: PE1
  /// at σ = 0.02 µm (γ 43 -> 6.7 µrad, f 1.15 -> 0.19 µm, S only 0.25 -> 0.16 µm: not "halved"),
  /// a 5 % gain, a periodic error at 0.1 µm, PE1 with a periodic error (core/refine_effects,
  /// core/refine_clean fail with it), and in the sweep (seeds 1-20, σ 0.05/0.1/0.2) halved runs
  /// pe1 8/1/0 -> 5/0/0, gain 3/0/0 -> 1/0/0, periodic 16/5/0 -> 13/2/0.
  bool apply_requires_identifiable = false;
  /// The final residual traced against the recorded variables (residual_trace.hpp): reported in
  /// RefineResult::trace and its findings; only a non-linearity is acted on (correct_nonlinearity).
  ResidualTraceOptions trace;
  /// Spikes and steps searched in the final residual (gross_errors.hpp).  When one is found and
  /// remove_gross_errors is set, `after` is the separation without them (their sizes' covariance
  /// in u_S): a gross error is not absorbed into S.
  GrossErrorOptions gross;
  bool remove_gross_errors = true;
  /// A sensor non-linearity the trace finds is corrected when decide_step expects S, γ, f to
  /// improve, else carried in u (sensor_nonlinearity.hpp); false: reported only.
  bool correct_nonlinearity = true;
  /// Declared bounds (Type B, see DeclaredEffectBound); empty: none, u_S carries only what the
  /// data show.  An effect not in the model enters u_S, u_γ, u_f with its posterior under the
  /// rectangular prior (covariance plus the square of the posterior mean: what the data leave of
  /// it is not corrected); for an effect in the model the bound sizes the parameter combinations
  /// the plan cannot determine (RefineStep::undetermined), when it is larger than the data's guess.
  std::vector<DeclaredEffectBound> declared;
  /// An effect's term in u (its fitted size or covariance, its undetermined part, what it does
  /// to the gauge directions) may change the readings by at most this many times their own RMS
  /// (about each sensor's mean); beyond it the data do not bound the effect: a correction is not
  /// applied, the term is held at the bound and RefineResult::unbounded says u_S is unbounded
  /// unless a bound is declared (refine.cpp kReadingBound).  0: no bound (u carries the fit).
  double reading_bound = 3.0;
  bool is_valid(std::string* why = nullptr) const;
};

/// What the simulation (or a reference instrument) says the answer is.
struct RefineTruth {
  Eigen::VectorXd f_um;       ///< N
  Eigen::VectorXd S_um;       ///< P
  Eigen::VectorXd gamma_rad;  ///< P
};

/// RMS errors against the truth after removing what one scan cannot see (issue 16): the best-fit
/// constant, line and bow of the difference for S and f (the bow of f trades with the bow of S, a
/// line of γ and a quadratic of e: the gauge "f has no bow" fixes it), constant and line for γ
/// (its constant is e_4/(D2+D3+D4), its line comes with the bow).
/// D minus its least-squares polynomial of degree `degree` in the sample index, column by column:
/// what remains of a profile (or of a profile's change) once the gauge directions are removed
/// (degree 2 for S and f: constant, line, bow; 1 for γ).
Eigen::MatrixXd remove_polynomial(const Eigen::MatrixXd& D, int degree);

struct ProfileErrors {
  double S_um = 0;
  double gamma_urad = 0;
  double f_um = 0;
};
ProfileErrors profile_errors(const FourSensorResult& r, const RefineTruth& truth);

struct CandidateScore {
  std::string effect;       ///< name()
  std::string description;  ///< of the best variant
  int parameters = 0;
  int identifiable = 0;
  double F = 0;
  double p_value = 1;  ///< after the look-elsewhere correction
  double trials = 1;   ///< effective number of variants tried
  double delta_rss_um2 = 0;
  Eigen::VectorXd relative_sv;  ///< identifiability: see check_identifiability
};

struct RefineStep {
  int index = 0;                ///< 0 = base model
  std::string effect = "base";  ///< name() of the added effect
  std::string description;
  std::vector<std::string> parameter_names;
  Eigen::VectorXd parameters, u_parameters;  ///< of the added effect, after the joint re-solve
  int identifiable = 0;  ///< directions determined (structurally and above direction_threshold)
  /// k × identifiable, orthonormal in parameter units: the combinations wᵀp of this effect's
  /// parameters the data determine in the joint model (wᵀp̂ estimates wᵀp whatever the part of
  /// the truth no scan can see; with all directions identifiable, the identity).  Also the
  /// relative singular values of the projected columns when scored.
  Eigen::MatrixXd identifiable_directions;
  Eigen::VectorXd relative_sv;
  /// Covariance of the added effect's estimate p̂ (parameter units², k × k, from σ̂ and the final
  /// linearisation): u(wᵀp̂) = sqrt(wᵀ·covariance·w) for every w above; u_parameters is its
  /// diagonal.
  Eigen::MatrixXd covariance;
  double F = 0, p_value = 1;
  double rss_before_um2 = 0, rss_after_um2 = 0;
  double rms_before_um = 0, rms_after_um = 0;  ///< RMS of the 4P reading residuals
  double sigma_after_um = 0;
  int dof_after = 0;
  int gauss_newton_iterations = 0;
  WhitenessTest whiteness_after;
  double dominant_period_mm = 0;  ///< of the residual after the step
  std::optional<ProfileErrors> error_before, error_after;
  std::vector<CandidateScore> candidates;  ///< the scores that chose this step (empty for base)
  /// Whether the added effect's correction is applied to the reported separation
  /// (step_decision.hpp); when not, the effect stays in the model of the residual and its fitted
  /// size goes into u_S, u_γ, u_f instead.
  bool applied = false;
  StepDecision decision;
  /// Parameter combinations of the added effect that this scan's plan cannot determine (k minus
  /// the determined ones), and the RMS change of S they would cause if each were as large as the
  /// determined ones are on average: 0 when they do not reach S (after the gauge).
  int undetermined = 0;
  double undetermined_S_um = 0;
  /// One line for the report: decision, figures, and "not identifiable from this plan" when
  /// undetermined_S_um matters.
  std::string verdict;
};

/// A significant candidate that was not added because its fitted parameters are physically
/// implausible (ModelEffect::implausibility): it "explains" the residual with values no real
/// instrument has, so something the library does not describe is in the data.
struct RejectedCandidate {
  int round = 0;  ///< loop round (number of effects in the model when it was scored)
  std::string effect;
  std::string description;
  std::vector<std::string> parameter_names;
  Eigen::VectorXd parameters, u_parameters;  ///< after the joint re-solve that was discarded
  double F = 0, p_value = 1;
  std::string reason;  ///< "rejected: implausible parameters (...)"
};

struct RefineResult {
  std::vector<RefineStep> steps;            ///< steps[0] is the base model
  std::vector<CandidateScore> final_round;  ///< scores when the loop stopped
  std::vector<RejectedCandidate> rejected;  ///< significant but implausible, not added
  /// Effects with implausible parameters kept only because the loop hit max_effects.
  std::vector<std::string> implausible_kept;
  std::string stop_reason;
  std::string model_name;  ///< "zhao2019-eq1" plus "+effect" for each addition
  std::vector<std::shared_ptr<const ModelEffect>> effects;  ///< added, in order
  std::vector<Eigen::VectorXd> parameters, u_parameters;    ///< per added effect (final)
  /// Covariance of all added effects' parameters (effect-major, as `parameters` concatenated)
  /// and the orthonormal combinations of them the data determine, from the final joint fit.
  Eigen::MatrixXd covariance, determined;
  /// Per added effect (final): the decision on its final parameters, whether it is applied, the
  /// report line.
  std::vector<StepDecision> decisions;
  std::vector<bool> applied;
  std::vector<std::string> verdicts;
  /// One line per effect whose term in u the data do not bound ("u_S unbounded: <effect> not
  /// determined by this plan; declare a bound (...)"): what it carries (its fitted size,
  /// covariance and undetermined part) would change the readings by more than
  /// RefineOptions::reading_bound (3) times their own RMS,
  /// so u_S holds it only at that size; a declared bound (RefineOptions::declared) sizes it.
  /// Empty: every term of u_S is bounded by the data.
  std::vector<std::string> unbounded;
  ResidualAnalysis residual;  ///< of the final model
  FourSensorResult before;    ///< separation of the raw readings (caller's options)
  /// The refined result: the separation of the readings corrected for the applied effects, with
  /// the gauge of `before` (constant, line and bow of S, constant and line of γ are those of the
  /// raw readings' separation: a step never moves what the data cannot see), and u_S, u_γ, u_f
  /// (and the covariance) carrying the applied parameters' covariance, the fitted size of the
  /// effects left out, the part of each effect this plan cannot determine, and what every effect
  /// did to the gauge directions of `before` (kept, so their error stays), and at least
  /// `before`'s covariance of those gauge directions (u_S_gauge_um: a correction's fresh
  /// separation has a lower σ̂, but the gauge directions kept did not get the correction).
  /// `before` when no effect was added.  When nothing is corrected (no effect applied, no gross
  /// error removed, no non-linearity corrected) S is `before`'s and u_S, u_γ are at least
  /// `before`'s at every point (tests/core/refine_u_raw.cpp).
  FourSensorResult after;
  Eigen::MatrixXd m_corrected_um;  ///< the readings `after` separates (applied effects only)
  Eigen::MatrixXd t_s;             ///< reading times used
  double alpha_per_candidate = 0;
  double alpha_residual = 0.01;  ///< level of the whiteness test (RefineOptions::residual.alpha)
  /// The final model's residual against time, position, configuration, reading level, direction
  /// and temperature, and the spikes and steps in it (see RefineOptions::gross).
  ResidualTrace trace;
  GrossErrorScan gross;
  bool gross_removed = false;     ///< `after` is the separation without the gross errors
  NonlinearityStep nonlinearity;  ///< the trace's non-linearity, corrected or carried in u
  /// P: what the declared bounds of effects not in the model add to u_S (quadrature; zeros when
  /// none is declared), and one line per declared bound saying what it added ("Type B").
  Eigen::VectorXd u_S_declared_um;
  std::vector<std::string> declared_notes;
  /// P: terms of the refined u_S (in quadrature, µm): what the added effects carry (their
  /// covariance if applied, their fitted size if not, the part the plan cannot determine and
  /// what they did to the gauge directions; zeros when none was added), and the gauge floor:
  /// what restores the raw separation's uncertainty of the constant, line and bow of S (and
  /// constant and line of γ) that the refined result keeps, when a correction's fresh separation
  /// (lower σ̂) holds less there (zeros when nothing was corrected).
  Eigen::VectorXd u_S_effects_um, u_S_gauge_um;
  /// True when the final residual passes the whiteness test.  False means the model is still
  /// missing something even if no candidate in the library was significant.
  bool residual_white() const { return residual.whiteness.white; }
  /// The verdict: the residual is white and no significant candidate had to be rejected as
  /// implausible (a rejection means the data hold something the library cannot describe).
  bool model_complete() const {
    return residual_white() && rejected.empty() && implausible_kept.empty() && !trace.depends &&
           !gross.found();
  }
  std::string brief_report() const;
};

/// Runs the loop on readings m (P × 4) with reading times t (P × 4, or empty for scan order).
/// `truth` (optional) adds the errors against it to every step.  `library` defaults to
/// default_effect_library().  Throws std::invalid_argument for bad shapes/options.
RefineResult refine_four_sensor(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                                const Eigen::MatrixXd& t_s = {}, const RefineOptions& opts = {},
                                const RefineTruth* truth = nullptr,
                                std::vector<std::unique_ptr<ModelEffect>> library = {});

/// Whether one effect of the library is identifiable from the plan used (issue 16 item 1: "the
/// effect is identifiable from the plan used"), computed from the design, the scan's times and
/// the noise the fit leaves (σ̂), never from the truth or from what the refine then does: the
/// effect (its best variant by the score) is fitted jointly with the base model of the raw
/// readings, and
///   - undetermined_S_um: how far the parameter combinations this plan cannot determine could
///     move S after the gauge (each as large as the determined ones are on average: RefineStep);
///   - predicted errors (RMS over the points, S in µm and γ in µrad) of the answer without the
///     correction, sqrt(u² + b²) with b² the bias estimate mean((D p̂)² − diag(D C Dᵀ)) taken at
///     its lower confidence bound (RefineOptions::decision.bias_z: the fit that estimates b is
///     the one that chose the effect), and with it, sqrt(u² + diag(D C Dᵀ) + undetermined²), u
///     the raw separation's standard uncertainty of the shape with σ̂ of the fit with the
///     effect, D the sensitivities of S and γ (gauge removed) and C the fitted parameters'
///     covariance (step_decision.hpp); evaluated at the fitted parameters and, linearised, about
///     zero (a non-linear effect weakly determined can fit far from its value), both must agree.
/// u is the raw separation's error of the shape (its covariance without the gauge directions,
/// which no step moves).
/// The effect is identifiable from the plan when its undetermined part does not reach S (at most
/// a tenth of u_S, the rule of the refine's "not identifiable from this plan") and the predicted
/// error with the correction is at most half the one without it, for S and for γ: then a step
/// can halve the error, otherwise the design and noise do not allow it whatever the decision.
struct EffectIdentifiability {
  std::string effect;       ///< name()
  std::string description;  ///< of the variant fitted
  int parameters = 0;
  int determined = 0;  ///< combinations the data determine (structurally)
  double undetermined_S_um = 0;
  /// RMS of the raw separation's u of the shape (S without constant, line and bow; γ without
  /// constant and line), from its covariance (the pointwise u where it has none).
  double u_S_um = 0, u_gamma_urad = 0;
  double predicted_S_before_um = 0, predicted_S_after_um = 0;
  double predicted_gamma_before_urad = 0, predicted_gamma_after_urad = 0;
  bool from_plan = false;     ///< undetermined_S_um <= 0.1 u_S_um
  bool identifiable = false;  ///< from_plan and both predicted errors at least halved
  std::string brief() const;  ///< one line
};
EffectIdentifiability effect_identifiability(const FourSensorConfig& cfg,
                                             const Eigen::MatrixXd& m_um,
                                             const Eigen::MatrixXd& t_s, const ModelEffect& effect,
                                             const RefineOptions& opts = {});

/// The options of a separation that is linear in the readings at the λ (and penalty) `sep` chose:
/// the change of S, γ, f per unit change of the readings, for sensitivities.
FourSensorOptions linearised_options(const FourSensorResult& sep, const FourSensorOptions& base);

/// The joint fit of given effects without any selection (what one step of the loop does for
/// the model it has chosen): Gauss–Newton from `start` (one vector per effect; empty = zeros).
struct EffectFit {
  std::vector<Eigen::VectorXd> parameters, u_parameters;  ///< per effect
  /// Covariance of all parameters (effect-major, parameter units²) and the orthonormal
  /// combinations the data determine (columns); see RefineStep.
  Eigen::MatrixXd covariance, determined;
  double rss_um2 = 0;
  double sigma_um = 0;
  int dof = 0;
  int iterations = 0;
  Eigen::MatrixXd m_corrected_um;
};
EffectFit fit_effects(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                      const Eigen::MatrixXd& t_s,
                      const std::vector<std::shared_ptr<const ModelEffect>>& effects,
                      const std::vector<Eigen::VectorXd>& start = {},
                      const RefineOptions& opts = {});

}  // namespace errsep::core

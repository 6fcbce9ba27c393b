#pragma once
// The four-sensor method of Zhao et al. 2019 end to end: assemble the system (Eqs. 3–16), choose λ,
// solve the Tikhonov problem (Eq. 17) with CHOLMOD, and recover S(x_n) and γ(x_n) (Eqs. 18–19),
// each with its uncertainty.  Pure computation: sensor outputs in, profiles with their diagnostics
// out.  The default estimator is the posterior of four_sensor_posterior.hpp (a smoothness prior
// on f, λ by REML, posterior covariance); the paper's own augmented system is kept for comparison.
#include <Eigen/Core>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "errsep/core/four_sensor_config.hpp"
#include "errsep/core/four_sensor_posterior.hpp"
#include "errsep/core/four_sensor_system.hpp"
#include "errsep/core/lcurve.hpp"
#include "errsep/core/tikhonov_solver.hpp"

namespace errsep::core {

enum class LambdaRule {
  /// Restricted maximum likelihood: the λ (prior precision) under which the data are most
  /// probable, σ held at the σ̂ of the redundant equations.  Needs log det of the normal matrix
  /// only.  The default (estimator posterior).
  reml,
  /// Generalised cross-validation: minimises n·‖AX_λ − b‖²/(n − edf)², edf from the selected
  /// inverse of the factor.  Estimator posterior only.
  gcv,
  lcurve,       ///< maximum curvature of the L-curve (the paper's choice)
  discrepancy,  ///< ‖AX_λ − b‖ = τ·δ, δ from the noise level estimated from the redundancy
  fixed,        ///< FourSensorOptions::fixed_lambda
  least_squares,  ///< λ = 0: the unregularised solution (the paper's Fig. 3(d))
};
const char* to_string(LambdaRule r);
/// The strings of to_string ("ls" is accepted for least_squares).
std::optional<LambdaRule> lambda_rule_from_string(std::string_view s);
/// Every rule's to_string, for option lists and messages.
std::vector<std::string> lambda_rule_names();

/// Which system is solved.
enum class Estimator {
  /// four_sensor_posterior.hpp: whitened rows, ends of f pinned, the bow fixed exactly, a prior
  /// on f (Penalty), posterior covariance.  The default.
  posterior,
  /// The paper's augmented system (Eqs. 5–16) with the chosen CurvatureGauge and RowWeighting,
  /// identity Tikhonov; its uncertainty is the covariance of the estimate for a fixed λ, which
  /// omits the shrinkage bias.  Kept to reproduce and compare with the paper.
  paper_system,
};
const char* to_string(Estimator e);
std::optional<Estimator> estimator_from_string(std::string_view s);

/// What LambdaRule::lcurve did when the curve had no corner to take (LCurveResult::has_corner).
enum class LambdaFallback {
  none,  ///< the corner was taken
  /// No corner and the null space is handled exactly (CurvatureGauge::reference_without_curvature):
  /// the unregularised solution is not noise-dominated, so none is applied (λ = the smallest
  /// that keeps the factorisation defined).
  no_regularisation,
  /// No corner with a gauge whose curvature row is weak (the bow is nearly null): λ from the
  /// discrepancy principle instead, since a small λ would leave the bow unregularised.
  discrepancy,
  /// Estimator posterior: the rule's λ shrank f to (almost) nothing — the largest λ of the
  /// range, or effective degrees of freedom of f below FourSensorOptions::collapse_edf — so S
  /// would inherit f's whole amplitude with an uncertainty that does not show it.  The
  /// unregularised separation with its exact covariance is reported instead.
  collapse_least_squares,
};
const char* to_string(LambdaFallback f);

/// How S and γ are taken from the outputs once f is known.
enum class MotionEstimator {
  /// Eq. (18) S = m_1 − f̄, Eq. (19) γ = [m_4 − m_1 − (f̄(x+O_4) − f̄(x))]/O_4 (without e_4).
  paper_eq18_19,
  /// Least-squares fit of S(x_n) + O_i·γ(x_n) to all four m_i − f̄(x_n + O_i) − ê_i, with ê from
  /// Δe = C·e (gauge e_1 = e_4 = 0, so γ carries the same constant e_4/O_4 as Eq. 19).  Averages
  /// the noise of four readings instead of two.
  all_configurations,
};

/// The λ search of LambdaRule::reml and gcv: a log grid (evaluated on `threads` threads), then a
/// refinement around the best grid point: its two neighbours at half the spacing (evaluated at
/// once on two threads), the best kept, the spacing halved.  λ is relative to the bound of
/// σ_max(A).  The defaults (one decade between grid points, 6 halvings: λ to 1/64 decade) find the
/// λ of a 201-point grid with 40 golden-section steps to within 0.01 decade on random profiles,
/// with 11 + 12 criteria instead of 21 + 12, and 12 sequential ones on two threads instead of 23.
struct LambdaSearchOptions {
  int count = 11;              ///< grid points (>= 3)
  double decades_below = 6.0;  ///< range [σ_max·10^−below, σ_max·10^above]
  double decades_above = 4.0;
  int refine_iterations = 6;  ///< halvings of the spacing in log λ
  int threads = 1;
  bool is_valid(std::string* why = nullptr) const;
};

struct FourSensorOptions {
  Estimator estimator = Estimator::posterior;
  Penalty penalty = Penalty::second_difference;  ///< estimator posterior: the prior on f
  LambdaRule rule = LambdaRule::reml;
  double fixed_lambda = 0.0;   ///< used with LambdaRule::fixed
  LambdaSearchOptions search;  ///< rules reml and gcv
  /// Estimator posterior: below this many effective degrees of freedom of f the prior has
  /// swallowed f (LambdaFallback::collapse_least_squares).
  double collapse_edf = 1.0;
  LCurveOptions lcurve;
  double discrepancy_tau = 1.0;
  CurvatureGauge gauge = CurvatureGauge::reference_without_curvature;
  RowWeighting weighting = RowWeighting::paper;
  MotionEstimator motion = MotionEstimator::all_configurations;
  /// Iterated Tikhonov steps X ← X + (AᵀA+λ²I)⁻¹Aᵀ(b − AX) with the same factor: each step
  /// multiplies the shrinkage bias λ²/(σ²+λ²) of every component by itself again.
  int iterated_refinements = 0;
  bool compute_uncertainty = true;  ///< per-point standard uncertainties u_f, u_S, u_γ
  /// Estimator paper_system: random probes when 4P is too large for exact propagation.
  int uncertainty_probes = 64;
  bool is_valid(std::string* why = nullptr) const;
};

struct FourSensorResult {
  FourSensorConfig config;
  Eigen::VectorXd x_mm;       ///< P slide positions x_n
  Eigen::VectorXd S_um;       ///< straightness error S(x_n)
  Eigen::VectorXd gamma_rad;  ///< tilt error γ(x_n), up to the constant e_4/(D2+D3+D4)
  Eigen::VectorXd f_x_mm;     ///< N reference positions
  Eigen::VectorXd f_um;       ///< reference profile f̄(x_n), with f(x_0) = f(x_{N−1}) = 0
  Eigen::Vector4d delta_e_um = Eigen::Vector4d::Zero();  ///< Δe = C·e (Eq. 10)
  Eigen::Vector4d e_um = Eigen::Vector4d::Zero();  ///< ê with e_1 = e_4 = 0 (see MotionEstimator)
  /// Standard uncertainties (k = 1), from σ̂: the posterior's for Estimator::posterior (prior
  /// included), for the paper's system those of the estimate at its λ (no shrinkage bias).
  Eigen::VectorXd u_S_um, u_gamma_rad, u_f_um;
  /// Estimator posterior with compute_uncertainty: covariances of linear functionals (ISO 230-1
  /// figures), from the kept factor.  Null otherwise.
  std::shared_ptr<FourSensorCovariance> covariance;
  /// Residual of every sensor reading after the fit, P × 4: m_i − f̄(x_n+O_i) − ê_i − S − O_i·γ.
  Eigen::MatrixXd sensor_residual_um;

  double lambda = 0;
  LambdaRule rule = LambdaRule::reml;
  Estimator estimator = Estimator::posterior;
  Penalty penalty = Penalty::second_difference;  ///< the prior used (none after a fallback)
  CurvatureGauge gauge = CurvatureGauge::reference_without_curvature;
  /// Effective degrees of freedom of the fit, tr(A(AᵀA + λ²P)⁻¹Aᵀ), and of f alone (estimator
  /// posterior; NaN when not computed).
  double edf = std::numeric_limits<double>::quiet_NaN();
  double edf_f = std::numeric_limits<double>::quiet_NaN();
  /// Rules reml and gcv: the λ of the search was at an end of its range or next to refused λ.
  bool lambda_at_edge = false;
  /// lambda_at_edge because the λ beyond the search's best were refused (the factor lost
  /// precision there), not because it is an end of the range: the minimum is not bracketed.
  bool lambda_at_refused_edge = false;
  /// What the data could not determine, in words (empty when nothing is to be said): the
  /// gauge, and after a collapse the level at which S is undetermined.
  std::string determination_note;
  LCurveResult lcurve;  ///< the whole curve (filled for rule lcurve)
  /// Rules reml and gcv: the λ of the search grid and the rule's criterion there.
  std::vector<double> lambda_grid, lambda_criterion;
  /// Rules reml and gcv: each λ the search could not evaluate and why, in the order tried
  /// ("lambda = 5.62 rejected: factor not positive definite at pivot …", FactorFailure::message):
  /// on long scans AᵀA + λ²P is singular to working precision at some λ.
  std::vector<std::string> lambda_rejected;
  /// Rule lcurve found no corner (lcurve.has_corner false): what was done instead.
  LambdaFallback lambda_fallback = LambdaFallback::none;
  double residual_norm = 0;  ///< ‖A·X_λ − b‖
  double solution_norm = 0;  ///< ‖X_λ‖
  double sigma_um = 0;       ///< sensor noise σ̂ implied by the redundant equations
  int redundancy_dof = 0;    ///< degrees of freedom behind σ̂: 2P − N + 1
  TikhonovSolverStats solver_stats;
  double total_s = 0;

  /// Whether λ shrinks the solution: false for least squares, λ = 0 and an L-curve without a
  /// corner that fell back to no regularisation (λ then only keeps the factorisation defined).
  bool regularised() const noexcept {
    return lambda > 0 && rule != LambdaRule::least_squares &&
           lambda_fallback != LambdaFallback::no_regularisation &&
           lambda_fallback != LambdaFallback::collapse_least_squares && penalty != Penalty::none;
  }
  /// One line: λ (rule), norms, σ̂, counts, time; flags an L-curve corner at the range edge.
  std::string brief_report() const;
};

/// The default options for a curvature gauge: the posterior estimator for the exact gauge
/// (reference_without_curvature), the paper's system with its L-curve for the others (the
/// posterior fixes the bow exactly and has no other gauge).
FourSensorOptions options_for_gauge(CurvatureGauge gauge);

/// Separates f, S and γ from outputs m (P × 4 µm, row n = slide position x_n, column i =
/// configuration i).  Throws std::invalid_argument for a bad configuration/shape or non-finite
/// data, std::runtime_error if the system cannot be solved.
FourSensorResult separate_four_sensor(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                                      const FourSensorOptions& opts = {});

/// The same when the combined outputs g(x_n) = C·m(x_n) of Eq. (9) are measured in their own
/// right (P × 4 µm, row n = g_1..g_4 at x_n), as when the combinations are formed in the
/// instrument: b₀ is taken from g, and m only for S and γ (Eqs. 18–19).  With g = C·m it is
/// separate_four_sensor(cfg, m, opts).  The uncertainties assume white noise on m.
FourSensorResult separate_four_sensor_combined(const FourSensorConfig& cfg,
                                               const Eigen::MatrixXd& m_um,
                                               const Eigen::MatrixXd& g_um,
                                               const FourSensorOptions& opts = {});

}  // namespace errsep::core

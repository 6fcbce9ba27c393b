#pragma once
// The four-sensor method of Zhao et al. 2019 end to end: assemble the augmented system (Eqs. 3–16),
// choose λ, solve the Tikhonov problem (Eq. 17) with CHOLMOD, and recover S(x_n) and γ(x_n)
// (Eqs. 18–19).  Pure computation: sensor outputs in, profiles with their diagnostics out.
#include <Eigen/Core>
#include <string>

#include "errsep/core/four_sensor_config.hpp"
#include "errsep/core/four_sensor_system.hpp"
#include "errsep/core/lcurve.hpp"
#include "errsep/core/tikhonov_solver.hpp"

namespace errsep::core {

enum class LambdaRule {
  lcurve,       ///< maximum curvature of the L-curve (the paper's choice)
  discrepancy,  ///< ‖AX_λ − b‖ = τ·δ, δ from the noise level estimated from the redundancy
  fixed,        ///< FourSensorOptions::fixed_lambda
  least_squares,  ///< λ = 0: the unregularised solution (the paper's Fig. 3(d))
};
const char* to_string(LambdaRule r);

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

struct FourSensorOptions {
  LambdaRule rule = LambdaRule::lcurve;
  double fixed_lambda = 0.0;  ///< used with LambdaRule::fixed
  LCurveOptions lcurve;
  double discrepancy_tau = 1.0;
  CurvatureGauge gauge = CurvatureGauge::reference_without_curvature;
  RowWeighting weighting = RowWeighting::paper;
  MotionEstimator motion = MotionEstimator::all_configurations;
  /// Iterated Tikhonov steps X ← X + (AᵀA+λ²I)⁻¹Aᵀ(b − AX) with the same factor: each step
  /// multiplies the shrinkage bias λ²/(σ²+λ²) of every component by itself again.
  int iterated_refinements = 0;
  bool compute_uncertainty = true;  ///< per-point standard uncertainties u_f, u_S, u_γ
  int uncertainty_probes = 64;      ///< random probes when 4P is too large for exact propagation
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
  Eigen::VectorXd u_S_um, u_gamma_rad, u_f_um;     ///< standard uncertainties (k = 1), from σ̂
  /// Residual of every sensor reading after the fit, P × 4: m_i − f̄(x_n+O_i) − ê_i − S − O_i·γ.
  Eigen::MatrixXd sensor_residual_um;

  double lambda = 0;
  LambdaRule rule = LambdaRule::lcurve;
  CurvatureGauge gauge = CurvatureGauge::reference_without_curvature;
  LCurveResult lcurve;  ///< the whole curve (filled for rule lcurve)
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
           lambda_fallback != LambdaFallback::no_regularisation;
  }
  /// One line: λ (rule), norms, σ̂, counts, time; flags an L-curve corner at the range edge.
  std::string brief_report() const;
};

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

#pragma once
// Planning a four-sensor scan (Zhao et al. 2019) for a target uncertainty of the straightness,
// before measuring (issue 15, item 4).
//
// Why it can be planned.  Without a prior the separation is linear in the readings, so its
// covariance depends on the geometry (spacings s2, s3, s4, the N samples of the reference) and
// the noise of one reading only, not on what is measured: predict_four_sensor_uncertainty
// (four_sensor_posterior.hpp) gives it exactly for a stated σ.  K samples averaged per point give
// σ/√K per reading (independent noise per sample), so every uncertainty scales as 1/√K.  The
// default estimator adds a smoothness prior on f, which can only tighten its posterior; the plan
// does not count on that (the reference may not be smooth).
//
// What "predicted straightness U" means.  An ISO 230-1 straightness is max − min of the
// deviations of S from a reference line, so its error is a combination c·δS with c ⟂ {1, x}
// (a line added to S does not change it): with the least-squares line, δT = δd(a) − δd(b), δd the
// error of S about its least-squares line and a, b the points that hold the extremes (the minimum
// zone puts one point against the interpolation between two others: the same bound below holds).
// The extremes lie where the profile puts them, unknown before measuring, so the prediction
// averages over every pair of positions:
//   u_T² = mean over (a, b) of Var(δd(a) − δd(b)) = 2·mean_x Var(δd(x))
// (the cross terms vanish because δd sums to zero over the positions), and U = k·u_T.  It is
// checked by simulation (tests/apps/plan_app.cpp: random profiles, noise on every reading, the
// default estimator, minimum-zone straightness): the fraction of runs within U of the truth is
// 90–99 %.  For extremes at the two worst points, sd(δd(a) − δd(b)) <= u_d(a) + u_d(b), so
// expanded_bound_um = k·2·max_x u_d(x) bounds U for any profile.
//
// The search.  The travel L and a sampling interval dx give P = L/dx + 1 slide positions; a
// configuration is three offsets 0 < a < b < T (in samples; s2 = a, s3 = b − a, s4 = T − b) that
// the sensor stage can reach, coprime (FourSensorConfig::is_valid), N = P + T >= 2T + 5.  The
// measuring effort is the number of readings 4·P·K.  For each candidate the predicted U with one
// sample per point, U₁, gives the K that reaches the target, K = ⌈(U₁/U_target)²⌉; the plan is the
// candidate with the fewest readings (then the lowest U).  Every candidate is evaluated when they
// are at most ScanPlanOptions::max_evaluations; otherwise an evenly spread sample of them, then
// a pattern search (steps halving to one sample) around the best few (ScanPlan::exhaustive false).
#include <Eigen/Core>
#include <string>
#include <vector>

#include "errsep/core/four_sensor_config.hpp"

namespace errsep::core {

/// What a four-sensor scan with a configuration will state, before measuring (file comment).
struct ScanPrediction {
  FourSensorConfig config;
  int averages = 1;              ///< K samples averaged per point
  double sigma_sample_um = 0.0;  ///< noise σ of one sample
  double sigma_um = 0.0;         ///< σ/√K: of one averaged reading
  double coverage_factor = 2.0;  ///< k
  Eigen::VectorXd x_mm;          ///< P slide positions
  Eigen::VectorXd u_S_um;        ///< standard uncertainty of S(x_n) (k = 1)
  /// Standard uncertainty of S(x_n) about its least-squares line, u_d (what a straightness sees).
  Eigen::VectorXd u_deviation_um;
  double u_straightness_um = 0.0;  ///< u_T = sqrt(2·mean u_d²)
  double expanded_um = 0.0;        ///< U = k·u_T
  double expanded_bound_um = 0.0;  ///< k·2·max u_d: U for extremes at the two worst points
  long long readings() const { return 4LL * config.positions() * averages; }
};

/// The prediction for `cfg` with noise `sigma_sample_um` per sample and `averages` samples per
/// point.  Throws std::invalid_argument for an invalid configuration, σ <= 0, K < 1 or k <= 0.
ScanPrediction predict_scan(const FourSensorConfig& cfg, double sigma_sample_um, int averages = 1,
                            double coverage_factor = 2.0);

/// The positions the sensor stage can take, relative to configuration 1.
struct SensorStageLimits {
  double range_mm = 100.0;  ///< largest offset D2 + D3 + D4 the stage can reach
  /// The offsets must be multiples of this (the stage's resolution or detent pitch); 0: any
  /// multiple of dx.
  double step_mm = 0.0;
  /// When not empty: the only positions the stage can take (absolute, mm; range and step unused).
  /// Configuration 1 may sit at any of them (ScanPlanCandidate::stage_origin_mm).
  std::vector<double> positions_mm;
};

struct ScanPlanOptions {
  double travel_mm = 1000.0;       ///< slide travel L to measure (a multiple of each dx)
  std::vector<double> dx_mm{5.0};  ///< candidate sampling intervals
  SensorStageLimits stage;
  /// Longest reference the set-up can hold, L0 = L + (s2 + s3 + s4)·dx; 0 = no limit.
  double reference_length_max_mm = 0.0;
  double sigma_um = 0.1;     ///< noise of one sample (one reading of the sensor)
  int averages_max = 100;    ///< K <= this
  double target_U_um = 1.0;  ///< target expanded uncertainty U of the straightness
  double coverage_factor = 2.0;
  /// Predictions evaluated at most (each costs O(N·(s2+s3+s4)²)); beyond, the sampled search.
  int max_evaluations = 10000;
  bool is_valid(std::string* why = nullptr) const;
};

struct ScanPlanCandidate {
  FourSensorConfig config;
  double stage_origin_mm = 0.0;         ///< stage position of configuration 1 (a listed one, or 0)
  double expanded_one_sample_um = 0.0;  ///< U₁: predicted U with one sample per point
  int averages = 1;          ///< K: the fewest that reach the target (averages_max when none does)
  double expanded_um = 0.0;  ///< U at K
  long long readings = 0;    ///< 4·P·K
};

struct ScanPlan {
  bool target_met = false;
  double target_U_um = 0.0;
  ScanPlanCandidate chosen;
  ScanPrediction prediction;  ///< of the chosen configuration at its K
  /// The paper's spacings (1, 1, 5) at the same travel, dx and K, for comparison (whether or not
  /// the stage could take them); no positions (x_mm empty) when the travel is too short for them.
  ScanPrediction baseline;
  std::vector<ScanPlanCandidate> runners_up;  ///< the next best, up to 5
  long long candidates = 0;                   ///< admissible configurations over all dx
  long long evaluated = 0;                    ///< of which predicted
  bool exhaustive = true;                     ///< every candidate was predicted
  std::vector<std::string> notes;             ///< dx values skipped and why, the search used
};

/// Searches the configurations the options allow (file comment).  Throws std::invalid_argument
/// for invalid options or when no dx leaves an admissible configuration (the message says why).
ScanPlan plan_four_sensor_scan(const ScanPlanOptions& opts);

/// The same report for one given configuration (no search): chosen = cfg at `averages`,
/// target_met against `target_U_um` (<= 0: no target, reported as met).
ScanPlan evaluate_scan_configuration(const FourSensorConfig& cfg, double sigma_um, int averages,
                                     double target_U_um, double coverage_factor = 2.0);

}  // namespace errsep::core

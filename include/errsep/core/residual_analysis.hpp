#pragma once
// What the four-sensor model leaves unexplained, and whether that is noise.
//
// Eq. (1) of Zhao et al. 2019 gives 4P readings; per slide position x_n the unknowns S(x_n) and
// γ(x_n) absorb any part of the four readings that is affine in the sensor offset O_i, so only the
// two combinations V₂ᵀ·m(x_n) orthogonal to span{1, O} carry information about f and e (the
// whitened rows of four_sensor_system.hpp).  The ordinary least-squares fit of f (N values) and e
// to those 2P numbers leaves dof = 2P − rank residual degrees of freedom (2P − N + 1 for the base
// model): the redundancy from which noise and missing effects are seen.
//
// ResidualSpace holds an orthonormal basis of the column space of the current model in that
// reduced space (base model, then each added effect's linearised columns), so residuals, F-tests
// and the Monte-Carlo calibration of the whiteness test are projections.  The residual of a least-
// squares fit is not white even for white noise ((I − H)·ε is correlated), so the whiteness
// statistics are calibrated by simulating (I − H)·ε with the same projector, which is exact for
// Gaussian noise whatever the model.
#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <string>

#include "errsep/core/four_sensor_config.hpp"

namespace errsep::core {

/// Orthonormal 4×2 basis V₂ of the complement of span{1, O} in R⁴ (O = configuration offsets).
Eigen::Matrix<double, 4, 2> residual_basis(const FourSensorConfig& cfg);

/// Reduced readings y (2P): y(2n + r) = V₂(:, r)ᵀ·m(x_n, :).  m is P × 4.
Eigen::VectorXd reduce_readings(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um);
/// Reduces columns given in reading space (4P × k, row 4n + i = configuration i at x_n).
Eigen::MatrixXd reduce_columns(const FourSensorConfig& cfg, const Eigen::MatrixXd& J);
/// The reading-space residual (P × 4) of a reduced residual (2P): V₂·r(x_n) per position.
Eigen::MatrixXd expand_residual(const FourSensorConfig& cfg, const Eigen::VectorXd& r);
/// A P × 4 matrix as a 4P column (row 4n + i), the layout of effect Jacobians.
Eigen::VectorXd stack_readings(const Eigen::MatrixXd& m_um);

/// The column space of a linear(ised) model of the reduced readings.
class ResidualSpace {
 public:
  /// The base model of Eq. (1): f(x_0..x_{N−1}) and e_1..e_4 (S and γ are already eliminated).
  explicit ResidualSpace(const FourSensorConfig& cfg);

  /// Adds reduced columns (2P × k).  Directions already in the space (relative size after
  /// projection below `rel_tol` of the column's norm) are not identifiable and are not added.
  /// Returns the number of directions added.
  int add(const Eigen::MatrixXd& reduced_columns, double rel_tol = 1e-6);

  /// y minus its projection onto the space.
  Eigen::VectorXd project_out(const Eigen::VectorXd& y) const;
  Eigen::MatrixXd project_out(const Eigen::MatrixXd& Y) const;

  int rows() const { return static_cast<int>(Q_.rows()); }
  int rank() const { return static_cast<int>(Q_.cols()); }
  int dof() const { return rows() - rank(); }
  const Eigen::MatrixXd& basis() const { return Q_; }
  const FourSensorConfig& config() const { return cfg_; }

 private:
  FourSensorConfig cfg_;
  Eigen::MatrixXd Q_;  // 2P × rank, orthonormal
};

/// How identifiable a set of columns is against a model: singular values of the projected,
/// column-normalised columns.
struct Identifiability {
  int parameters = 0;               ///< k
  int identifiable = 0;             ///< directions with relative singular value above tolerance
  Eigen::VectorXd relative_sv;      ///< singular values of (I − H)·J·D⁻¹ (D = column norms)
  Eigen::MatrixXd null_directions;  ///< k × (k − identifiable), in parameter units
};
Identifiability check_identifiability(const ResidualSpace& space, const Eigen::MatrixXd& reduced_J,
                                      double rel_tol = 1e-6);

struct ResidualAnalysisOptions {
  int lags = 10;           ///< Ljung–Box lags (capped at P/4)
  int mc_samples = 400;    ///< Monte-Carlo draws of (I − H)·ε for the whiteness p-values
  double alpha = 0.01;     ///< the residual is called white when the whiteness p-value >= alpha
  std::uint64_t seed = 7;  ///< Monte-Carlo seed (fixed: the same data give the same report)
  bool is_valid(std::string* why = nullptr) const;
};

/// Whiteness of the residual: five statistics, each sensitive to a different departure from
/// white noise, combined by the minimum of their p-values.  Every p-value is Monte-Carlo
/// calibrated against (I − H)·ε drawn with the current model's projector (see the top of the
/// file), and so is the minimum itself (the data and the draws are pooled and ranked: an exact
/// level-α test for Gaussian noise, no Bonferroni loss), so on a complete model the residual is
/// called not white in a fraction α of scans.
///   - Ljung–Box (Box & Pierce portmanteau with the Ljung–Box weights) of each configuration's
///     residual in position order, summed: serial correlation along x.
///   - Periodogram max / mean of the configuration-summed periodogram: one sharp period.
///   - Cumulative periodogram (Bartlett's test; Kolmogorov–Smirnov distance of the normalised
///     cumulative periodogram from the diagonal): broadband, e.g. a red (low-frequency) residual.
///   - Runs (Wald–Wolfowitz) of the signs of the residual in time order, standardised so that
///     too FEW runs is large: slowly varying structure in time (drift, a traverse that differs).
///   - Local excess: the largest standardised window sum of the per-position residual energy
///     (windows of 1, 2, 3, 5, 8 positions, each scaled by its null variance, Wilson–Hilferty
///     z), which finds structure confined to a few positions (a bump, a scratch, dust) that the
///     global statistics dilute.
struct WhitenessTest {
  double ljung_box_q = 0;  ///< Σ over configurations of Q = n(n+2)Σ_k ρ_k²/(n−k), position order
  double p_ljung_box = 1;               ///< Monte-Carlo p-value of Q under the current model
  double periodogram_ratio = 0;         ///< max / mean of the configuration-summed periodogram
  double p_periodogram = 1;             ///< Monte-Carlo p-value of that ratio
  double cumulative_periodogram_d = 0;  ///< Bartlett KS distance
  double p_cumulative_periodogram = 1;
  double runs_z = 0;  ///< (expected − observed runs)/sd of the time-ordered signs
  double p_runs = 1;
  double local_z = 0;  ///< largest standardised window energy
  double p_local = 1;
  double local_x_mm = 0;      ///< centre of that window, n·Δx from the first position
  double local_width_mm = 0;  ///< its width (positions × Δx)
  double p_value = 1;         ///< Monte-Carlo p-value of the smallest of the five p-values
  std::string rejected_by;    ///< names of the statistics with p < alpha (empty when white)
  int lags = 0;
  int mc_samples = 0;
  bool white = true;  ///< p_value >= alpha
};

struct ResidualAnalysis {
  Eigen::MatrixXd residual_um;  ///< P × 4, reading space, row = position, column = config
  Eigen::Vector4d rms_per_config_um = Eigen::Vector4d::Zero();
  Eigen::VectorXd rms_per_position_um;     ///< P
  Eigen::VectorXd time_s;                  ///< 4P reading times, ascending
  Eigen::VectorXd residual_time_order_um;  ///< 4P residuals in that order
  double rss_um2 = 0;                      ///< residual sum of squares
  int dof = 0;                             ///< redundancy: rows − rank of the model
  double sigma_um = 0;                     ///< σ̂ = sqrt(RSS/dof)
  double rms_um = 0;                       ///< sqrt(RSS/4P), the RMS of the reading residuals
  WhitenessTest whiteness;
  Eigen::VectorXd periodogram_period_mm;  ///< periods P·Δx/k, k = 1..P/2
  Eigen::VectorXd periodogram_power;      ///< configuration-summed |DFT|² of the residual
  double dominant_period_mm = 0;          ///< period of the largest periodogram ordinate
};

/// Residual of the readings `m_um` (P × 4, already corrected for any added effects) against the
/// model `space`, its noise level, whiteness and spectrum.  `t_s` (P × 4, may be empty) orders the
/// readings in time; empty means the scan order of the single-sensor system.  Throws
/// std::invalid_argument on shape mismatch or invalid options.
ResidualAnalysis analyse_residual(const ResidualSpace& space, const Eigen::MatrixXd& m_um,
                                  const Eigen::MatrixXd& t_s = {},
                                  const ResidualAnalysisOptions& opts = {});

/// Whiteness statistics of a reading-space residual (P × 4) without calibration (used by
/// analyse_residual for the data and for every Monte-Carlo draw).
void whiteness_statistics(const Eigen::MatrixXd& residual_um, int lags, double* ljung_box_q,
                          double* periodogram_ratio, Eigen::VectorXd* power = nullptr);

/// Default reading times of the single-sensor system when none were recorded: configuration i
/// (0-based) is the i-th traverse at speed v, so t = i·T + x_n/v with T = P·Δx/v.
Eigen::MatrixXd scan_order_times_s(const FourSensorConfig& cfg, double speed_mm_per_s = 10.0);

}  // namespace errsep::core

namespace errsep::core {

/// A residual of any linear model whose noise is independent and identically distributed per
/// equation: r = Π·ε with Π the orthogonal projector onto the complement of the model's columns.
/// Laid out as C channels observed at the same L instants (L × C, rows in time order), e.g. the
/// sensors of the displacement method's redundant equations (displacement_residuals.hpp).
struct ProjectedResidual {
  Eigen::MatrixXd residual;  ///< L × C
  /// Π applied to an L × C matrix (used on independent N(0, 1) draws for the calibration).
  std::function<Eigen::MatrixXd(const Eigen::MatrixXd&)> project;
  /// L × C: the diagonal of Π per channel (1 − leverage of each equation); its column sums are
  /// the channels' degrees of freedom.
  Eigen::MatrixXd projector_diagonal;
};

/// The five whiteness statistics of analyse_residual, for a ProjectedResidual, with the same
/// Monte-Carlo calibration (draws of Π·ε, pooled ranks, the minimum p-value's own rank).  The
/// statistics are taken of the time series: Ljung–Box per channel in time order (summed),
/// periodogram peak and Bartlett's cumulative periodogram of the channel-summed periodogram along
/// time, runs of the signs in time order (channels of one instant in column order), local excess
/// over windows of consecutive instants.  Each channel is first scaled by its own σ̂ (RSS over its
/// degrees of freedom), in the data and in every draw alike, so channels of different noise
/// (sensors of different kinds) weigh alike and the test stays calibrated.  local_x_mm and
/// local_width_mm are in rows (instants): the window's centre row and its length.  `power` (if
/// given) receives the channel-summed periodogram of the scaled residual, frequencies k/L,
/// k = 1..L/2.  Throws std::invalid_argument on inconsistent shapes or invalid options.
WhitenessTest test_projected_whiteness(const ProjectedResidual& r,
                                       const ResidualAnalysisOptions& opts = {},
                                       Eigen::VectorXd* power = nullptr);

}  // namespace errsep::core

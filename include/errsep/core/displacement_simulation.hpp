#pragma once
// Seeded simulation of the displacement method's scans (Haramiishi et al. 2024): one axis
// (Eqs. 1-3, section 2.3.1) and the x-y stage (Eqs. 10-19 with roll and pitch), plus a
// three-sensor slideway scan for comparing methods.  Sensor errors: Gaussian noise per reading,
// linear zero drift over time (scan 2 follows scan 1, so drift enters the differences of Eq. 4),
// and an error in the traverse d of the reference piece (systematic and/or one random draw per
// second scan: the reference piece is traversed once, by a micrometre, section 2.3.2).
//
// Randomness: one NoiseSource (std::mt19937_64) per call, seeded by the options; draws are made in
// a fixed order (scan 1 samples in scan order, then the d error, then scan 2), so a seed fixes
// every reading.
#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <string>

#include "errsep/core/displacement_effects.hpp"
#include "errsep/core/two_axis_displacement.hpp"

namespace errsep::core {

/// A profile along one axis, position in mm -> value (µm or rad as named).
using AxisFn = std::function<double(double mm)>;
/// A function on the x-y grid, (x mm, y mm) -> value.
using GridFn = std::function<double(double x_mm, double y_mm)>;

struct SensorErrorModel {
  double noise_sigma_um = 0.0;  ///< standard deviation of the Gaussian noise on every reading
  double drift_um_per_s = 0.0;  ///< zero drift rate: offset = rate · t since the first sample
  bool is_valid(std::string* why = nullptr) const;
};

struct ScanTiming {
  double sample_period_s = 1.0;        ///< time per sample
  double pause_between_scans_s = 0.0;  ///< time to traverse the reference pieces between scans
};

// ---- one axis ---------------------------------------------------------------------------------

struct OneAxisTruth {
  AxisFn w_um;  ///< workpiece profile w(x)
  AxisFn r_um;  ///< reference piece profile r(x) (evaluated up to x_max + d + d error)
  AxisFn m_um;  ///< table motion error m(x)
};

struct OneAxisSimOptions {
  double sample_interval_mm = 5.0;     ///< Δx
  double length_mm = 120.0;            ///< samples at 0, Δx, ..., length (inclusive)
  double displacement_mm = 5.0;        ///< nominal d
  double displacement_bias_mm = 0.0;   ///< systematic error of the traverse
  double displacement_sigma_mm = 0.0;  ///< random error of the traverse (one draw per run)
  SensorErrorModel workpiece_sensor;   ///< sensor 1
  SensorErrorModel reference_sensor;   ///< sensor 2
  ScanTiming timing;
  std::uint64_t seed = 1;
  /// Scan 2 runs from the last point back to the first (times only: the draws are unchanged).
  bool reverse_scan2 = false;
  /// Undeclared first-order thermal drift a·(1 − exp(−t/τ)) of the workpiece sensor 1 and the
  /// reference sensor 2 (displacement_refine_one_axis.hpp), added after every draw.
  double workpiece_thermal_um = 0, reference_thermal_um = 0, thermal_tau_s = 600.0;
  bool is_valid(std::string* why = nullptr) const;
};

struct OneAxisSimData {
  Eigen::VectorXd x_mm;
  Eigen::VectorXd s1_1_um, s2_1_um, s2_2_um;  ///< Eqs. (1)-(3) plus sensor errors
  Eigen::VectorXd w_um, r_um, m_um;           ///< truth at x_k
  double applied_displacement_mm = 0;         ///< the traverse actually made
  /// The workpiece sensor during scan 2 (Eq. 1 again: the workpiece is not traversed), as
  /// errsep-scan records it.  Drawn after every other reading, so the others do not depend on it.
  Eigen::VectorXd s1_2_um;
  Eigen::VectorXd t1_s, t2_s;  ///< time of each reading of scan 1 and scan 2 (s)
};

/// Throws std::invalid_argument if the options are invalid or a truth function is empty.
OneAxisSimData simulate_one_axis(const OneAxisTruth& truth, const OneAxisSimOptions& opts);

/// Section 2.3.1 / Fig. 5 inputs: w a square wave of 500 µm height (period 40 mm), m a sinusoid of
/// 20 µm amplitude (period 120 mm), r linear (0.05 µm/mm).  Periods and slope are not printed in
/// the paper; these are this module's choice.
OneAxisTruth haramiishi2024_fig5_truth();

// ---- two axes -----------------------------------------------------------------------------------

/// Motion of the stage.  The x table moves by ez_x and rolls by roll_x about the x axis; the y
/// table moves by ez_y and pitches by pitch_y about the y axis (each may depend on x and y: the
/// y table's load moves with y).  Along the line of sensors 2 -> 1 -> 0 the x-table height is
/// ez_x + roll_x·s (s signed from sensor 2, as in TwoAxisGeometry); along sensors 4 -> 3 -> 0 the
/// y-table height is ez_y + pitch_y·s.  The x table's pitch and the y table's roll are common to
/// all sensors of a pair and to sensor 0 (sensors 1, 2, 0 share x; 3, 4, 0 share y), so they are
/// part of ez_x and ez_y.
struct TwoAxisTruth {
  GridFn w_um;
  AxisFn r1x_um, r2x_um;  ///< reference piece X, tracks of sensors 1 and 2 (functions of x)
  AxisFn r3y_um, r4y_um;  ///< reference piece Y, tracks of sensors 3 and 4 (functions of y)
  GridFn ez_x_um, roll_x_rad, ez_y_um, pitch_y_rad;
};

struct TwoAxisSimOptions {
  int nx = 25, ny = 25;  ///< grid size (paper: 120 mm at 5 mm -> 25 x 25)
  double dx_mm = 5.0, dy_mm = 5.0;
  double displacement_x_mm = 5.0, displacement_y_mm = 5.0;
  double displacement_bias_mm = 0.0;   ///< systematic error of both traverses
  double displacement_sigma_mm = 0.0;  ///< random error, one draw per reference piece
  TwoAxisGeometry geometry;            ///< lever arms the simulated sensors really sit at
  SensorErrorModel contact_sensor;     ///< sensor 0
  SensorErrorModel eddy_sensor;        ///< sensors 1-4 (independent draws per sensor)
  ScanTiming timing;                   ///< raster: x fastest, then y; scan 2 after scan 1
  std::uint64_t seed = 1;
  /// Also read sensor 0 during scan 2 (TwoAxisScan::s0_2_um), drawn after every other reading.
  bool record_s0_scan2 = false;
  /// Scan 2 runs the raster backwards (TwoAxisScanOrder); the drift above follows its times.
  bool reverse_scan2 = false;
  /// Scan 2's raster runs y fastest (TwoAxisScanOrder::y_fastest_scan2).
  bool y_fastest_scan2 = false;
  /// Scan 1 along wrapped diagonals (TwoAxisScanOrder::diagonal_scan1).
  bool diagonal_scan1 = false;
  /// Undeclared effects (displacement_effects.hpp) added after every draw: they change no draw.
  DisplacementDisturbance disturbance;
  bool is_valid(std::string* why = nullptr) const;
};

struct TwoAxisSimData {
  TwoAxisScan scan;              ///< what the sensors read
  Eigen::MatrixXd w_um, m_w_um;  ///< truth: workpiece, and motion under sensor 0
};

TwoAxisSimData simulate_two_axis(const TwoAxisTruth& truth, const TwoAxisSimOptions& opts);

/// A stage with straightness, roll and pitch of a few µm / tens of µrad, a bowl-and-ripple
/// workpiece and gently curved reference pieces (this module's choice, sized like the paper's
/// 120 mm x 120 mm stage).
TwoAxisTruth example_two_axis_truth();

// ---- three-sensor slideway scan (for the three-point method) ----------------------------------

struct SlidewayProfiles {
  AxisFn f_um;       ///< surface profile
  AxisFn S_um;       ///< straightness of the slide
  AxisFn gamma_rad;  ///< tilt of the slide
};

struct ThreeSensorSimOptions {
  int positions = 23;  ///< P slide positions x_n = nΔx
  double sample_interval_mm = 5.0;
  int s1 = 1, s2 = 1;       ///< sensor spacings in Δx
  SensorErrorModel sensor;  ///< the same for the three sensors, independent draws
  std::uint64_t seed = 1;
};

/// Readings m_j(x_n) = f(x_n + O_j) + S(x_n) + O_j·γ(x_n) + noise, P × 3 (Zhao 2019 Eq. 1 with
/// zero-adjustment values 0).  Drift uses sample_period 1 s per slide position.
Eigen::MatrixXd simulate_three_sensor(const SlidewayProfiles& truth,
                                      const ThreeSensorSimOptions& opts);

}  // namespace errsep::core

#pragma once
// CSV layouts of the displacement and three-point methods (errsep-separate-displacement).
//
// Column names follow the raw-scan CSV (io/raw_scan_csv.hpp): sN_scanK_um = sensor N, scan K.
// One axis (Haramiishi 2024 Eqs. 1-3), one row per position, uniform x: either a raw scan written
// by errsep-scan ("# format: errsep raw displacement scan", read by read_raw_displacement_csv,
// "# d_mm:" required, incomplete scans refused), or any CSV with
//   x_mm, s1_scan1_um (workpiece), s2_scan1_um (reference), s2_scan2_um (reference after the
//   traverse d)        and an optional "# d_mm: <d>" line
//   optional: s1_scan2_um (the workpiece sensor during scan 2; a raw scan always has it), which
//   makes Eq. (1) redundant (core/displacement_residuals.hpp)
// Two axes (Eqs. 10-19), one row per grid point, any order, every (x, y) exactly once:
//   x_mm, y_mm, s0_scan1_um, s1_scan1_um, s1_scan2_um, s2_scan1_um, s2_scan2_um, s3_scan1_um,
//   s3_scan2_um, s4_scan1_um, s4_scan2_um
//   optional: s0_scan2_um (sensor 0 during scan 2, makes Eq. 10 redundant); t_scan1_s (when scan 1
//   read the point; orders the residuals in time, default x fastest then y); the lateral sensor
//   pair of core/two_axis_yaw.hpp, all four or none: sa_scan1_um, sa_scan2_um, sb_scan1_um,
//   sb_scan2_um
// Three-point (Zhao 2019 Eq. 1), one row per slide position, uniform x:
//   x_mm, m1_um, m2_um, m3_um   (sensors at 0, s1·Δx, (s1 + s2)·Δx)
// Extra columns are ignored.  Problems are reported as CsvError "file:line: what is wrong".
#include <filesystem>
#include <optional>

#include "errsep/core/displacement_joint.hpp"
#include "errsep/core/displacement_method.hpp"
#include "errsep/core/displacement_residuals.hpp"
#include "errsep/core/displacement_scan_order.hpp"
#include "errsep/core/three_point_method.hpp"
#include "errsep/core/two_axis_displacement.hpp"
#include "errsep/core/two_axis_yaw.hpp"
#include "errsep/io/csv.hpp"

namespace errsep::io {

struct OneAxisInput {
  Eigen::VectorXd x_mm, s1_1_um, s2_1_um, s2_2_um;
  Eigen::VectorXd s1_2_um;     ///< workpiece sensor in scan 2; empty when the file has none
  double dx_mm = 0;            ///< sampling interval found in the file
  std::optional<double> d_mm;  ///< the traverse d, when the file records it (# d_mm:)
  /// The order scan 2 read the points in (a raw scan's "# scan2_order:"; else forward).
  core::DisplacementScanOrder scan2_order = core::DisplacementScanOrder::forward;
};

struct TwoAxisInput {
  core::TwoAxisScan scan;  ///< scan.s0_2_um empty when the file has no s0_scan2_um
  double dx_mm = 0, dy_mm = 0;
  Eigen::MatrixXd t_scan1_s;                     ///< nx × ny, empty when the file has none
  std::optional<core::LateralPairScan> lateral;  ///< when the file has the four sa/sb columns
};

struct ThreePointInput {
  Eigen::VectorXd x_mm;
  Eigen::MatrixXd m_um;  ///< P × 3
  double dx_mm = 0;
};

/// Throws CsvError on a missing column, a non-finite or malformed value, fewer than 2 rows, or x
/// not strictly increasing at a constant interval (naming the first offending line).
OneAxisInput read_one_axis_csv(const std::filesystem::path& file);
/// Throws CsvError on a missing column, bad values, a duplicated (x, y) (its line), a ragged grid
/// (names a missing point), non-uniform x or y spacing, or only some of the lateral pair's four
/// columns.
TwoAxisInput read_two_axis_csv(const std::filesystem::path& file);
/// As read_one_axis_csv for the three-point layout.
ThreePointInput read_three_point_csv(const std::filesystem::path& file);

/// x_mm, r_um, m_um, w_um.
CsvTable one_axis_result_csv(const Eigen::VectorXd& x_mm, const core::DisplacementResult& r);
/// The joint estimate: the columns above, then u_r_um, u_m_um, u_w_um when a σ is known;
/// metadata: gauge, σ and where it came from.
CsvTable one_axis_result_csv(const Eigen::VectorXd& x_mm, const core::OneAxisJointResult& r);
/// x_mm, y_mm, w_um, m_w_um, m1x_um, m2x_um, m3y_um, m4y_um, m_wxe_um, m_wye_um, r1x_um, r2x_um,
/// r3y_um, r4y_um; with the joint solver also u_w_um, u_m_w_um, u_m1x_um … u_r4y_um (standard
/// uncertainties), σ̂, gauge and rotation decision in the metadata; rows with x fastest, then y.
CsvTable two_axis_result_csv(const core::TwoAxisScan& scan, const core::TwoAxisResult& r);
/// The residuals of the redundant equations, one row per equation:
///   family, sensor, scan, run, order, x_mm[, y_mm], value_um, residual_um
/// family: 1-based index into `r.families` (named in the metadata); sensor: the paper's number;
/// scan: 1 or 2 for a single reading, 0 for the difference of the two scans; run: 1-based in a
/// repeated-runs family, else 0 (mean of the runs); order: the equation's place in time within its
/// family.  Metadata: σ̂ with dof and interval per family and channel, the whiteness verdict with
/// its p-values, the fitted offset of a workpiece repeat, the overall verdict.
CsvTable displacement_residuals_csv(const core::DisplacementResiduals& r, bool two_axis);

/// Profile: x_mm, f_um (N rows).
CsvTable three_point_profile_csv(double x0_mm, double dx_mm, const core::ThreePointResult& r);
/// Slide motion: x_mm, S_um, gamma_urad (P rows).
CsvTable three_point_motion_csv(const Eigen::VectorXd& x_mm, const core::ThreePointResult& r);

}  // namespace errsep::io

#pragma once
// CSV layouts of the displacement and three-point methods (errsep-separate-displacement).
//
// Column names follow the raw-scan CSV (io/raw_scan_csv.hpp): sN_scanK_um = sensor N, scan K.
// One axis (Haramiishi 2024 Eqs. 1-3), one row per position, uniform x: either a raw scan written
// by errsep-scan ("# format: errsep raw displacement scan", read by read_raw_displacement_csv,
// "# d_mm:" required, incomplete scans refused), or any CSV with
//   x_mm, s1_scan1_um (workpiece), s2_scan1_um (reference), s2_scan2_um (reference after the
//   traverse d)        and an optional "# d_mm: <d>" line
// Two axes (Eqs. 10-19), one row per grid point, any order, every (x, y) exactly once:
//   x_mm, y_mm, s0_scan1_um, s1_scan1_um, s1_scan2_um, s2_scan1_um, s2_scan2_um, s3_scan1_um,
//   s3_scan2_um, s4_scan1_um, s4_scan2_um
// Three-point (Zhao 2019 Eq. 1), one row per slide position, uniform x:
//   x_mm, m1_um, m2_um, m3_um   (sensors at 0, s1·Δx, (s1 + s2)·Δx)
// Extra columns are ignored.  Problems are reported as CsvError "file:line: what is wrong".
#include <filesystem>
#include <optional>

#include "errsep/core/displacement_method.hpp"
#include "errsep/core/three_point_method.hpp"
#include "errsep/core/two_axis_displacement.hpp"
#include "errsep/io/csv.hpp"

namespace errsep::io {

struct OneAxisInput {
  Eigen::VectorXd x_mm, s1_1_um, s2_1_um, s2_2_um;
  double dx_mm = 0;            ///< sampling interval found in the file
  std::optional<double> d_mm;  ///< the traverse d, when the file records it (# d_mm:)
};

struct TwoAxisInput {
  core::TwoAxisScan scan;
  double dx_mm = 0, dy_mm = 0;
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
/// (names a missing point) or non-uniform x or y spacing.
TwoAxisInput read_two_axis_csv(const std::filesystem::path& file);
/// As read_one_axis_csv for the three-point layout.
ThreePointInput read_three_point_csv(const std::filesystem::path& file);

/// x_mm, r_um, m_um, w_um.
CsvTable one_axis_result_csv(const Eigen::VectorXd& x_mm, const core::DisplacementResult& r);
/// x_mm, y_mm, w_um, m_w_um, m1x_um, m2x_um, m3y_um, m4y_um, m_wxe_um, m_wye_um, r1x_um, r2x_um,
/// r3y_um, r4y_um; rows with x fastest, then y.
CsvTable two_axis_result_csv(const core::TwoAxisScan& scan, const core::TwoAxisResult& r);
/// Profile: x_mm, f_um (N rows).
CsvTable three_point_profile_csv(double x0_mm, double dx_mm, const core::ThreePointResult& r);
/// Slide motion: x_mm, S_um, gamma_urad (P rows).
CsvTable three_point_motion_csv(const Eigen::VectorXd& x_mm, const core::ThreePointResult& r);

}  // namespace errsep::io

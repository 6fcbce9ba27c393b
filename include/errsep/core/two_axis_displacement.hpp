#pragma once
// Two-axis (x-y stage) displacement method with roll/pitch correction, Haramiishi et al. 2024,
// section 2.2, Eqs. (10)-(27).
//
// Sensors 0, 1, 2 are fixed to the base; sensors 3, 4 ride on the x table, which carries the
// y table and the workpiece.  Sensor 0 reads the workpiece w(x, y); sensors 1, 2 read reference
// piece X (tracks r1_x, r2_x) on the x table; sensors 3, 4 read reference piece Y (r3_y, r4_y)
// on the y table.  Scan 1 reads all five sensors (Eqs. 10-14); scan 2 repeats with reference X
// traversed by d_x and reference Y by d_y (Eqs. 16-19).  Each reference sensor then gives r and
// m by the one-axis method (Eq. 9 along x for sensors 1, 2 on every row y_j; along y for sensors
// 3, 4 on every column x_i).
//
// Rotation correction, Eqs. (22)-(27), as read here:
//   Δm_x = m2_x - m1_x                       (22)
//   m_wxe = Δm_x · l_xw / l_xs              (24)   l_xs: sensor 1 to sensor 2; l_xw: sensor 2
//                                                   to sensor 0, positive in the direction from
//                                                   sensor 2 toward sensor 1 (the sign that makes
//                                                   Eq. 23 the straight-line extrapolation
//                                                   m_wx = m2_x - m_wxe through m1_x and m2_x)
//   Δm_y = m4_y - m3_y,  m_wye = Δm_y · l_yw / l_ys    (26)  the paper's "Δm_y is the difference
//                                                   between m?_y and m?_y" and "l_yw between
//                                                   sensors 3 and 0" are garbled; by symmetry
//                                                   with Eqs. 22-24 (Eq. 25 starts from m4_y) we
//                                                   measure l_yw from sensor 4 toward sensor 3.
//   m_w = m2_x + m4_y - m_wxe - m_wye        (27),   w = S0_1 - m_w   (10)
//
// Lever arm of the y correction: sensors 3, 4 ride on the x table but sensor 0 is fixed to the
// base, so the x-distance from sensor 4 to sensor 0 changes by the x travel.  The paper uses a
// constant l_yw; `l_yw_per_x` (default 0 = the paper) lets l_yw(x) = l_yw + l_yw_per_x · (x - x_0).
//
// Grids: matrices are nx × ny with element (i, j) at (x_i, y_j).
#include <Eigen/Core>
#include <string>

#include "errsep/core/displacement_method.hpp"

namespace errsep::core {

struct TwoAxisGeometry {
  double l_xs_mm = 30.0;    ///< sensor 1 to sensor 2 (paper: 30 mm)
  double l_xw_mm = 165.0;   ///< sensor 2 to sensor 0, signed as above (paper: 165 mm)
  double l_ys_mm = 30.0;    ///< sensor 3 to sensor 4 (paper: 30 mm)
  double l_yw_mm = 165.0;   ///< sensor 4 to sensor 0 at x_0, signed as above (paper: 165 mm)
  double l_yw_per_x = 0.0;  ///< d l_yw / dx (0 = paper's constant lever arm)
};

struct TwoAxisOptions {
  double dx_mm = 5.0;              ///< sampling interval along x
  double dy_mm = 5.0;              ///< sampling interval along y
  double displacement_x_mm = 5.0;  ///< d for reference piece X (integer multiple of dx_mm)
  double displacement_y_mm = 5.0;  ///< d for reference piece Y (integer multiple of dy_mm)
  TwoAxisGeometry geometry;
  /// Apply Eqs. (22)-(27).  false = Eqs. (20)-(21): m_w = m2_x + m4_y (the paper's Fig. 22).
  bool correct_rotation = true;
  ChainJoin chain_join = ChainJoin::least_roughness;

  bool is_valid(std::string* why = nullptr) const;
};

/// Sensor outputs on an nx × ny grid.  SN_n = sensor N, scan n (paper's notation).
struct TwoAxisScan {
  Eigen::VectorXd x_mm;  ///< nx grid positions, x_i = x_0 + i·dx
  Eigen::VectorXd y_mm;  ///< ny grid positions
  Eigen::MatrixXd s0_1_um, s1_1_um, s1_2_um, s2_1_um, s2_2_um, s3_1_um, s3_2_um, s4_1_um, s4_2_um;
  /// Sensor 0 read during scan 2 as well (optional, empty when not recorded).  Eqs. (10)-(27) do
  /// not use it; it makes Eq. (10) redundant (displacement_residuals.hpp).
  Eigen::MatrixXd s0_2_um;
};

struct TwoAxisResult {
  Eigen::MatrixXd w_um;                            ///< workpiece profile, Eq. (10) with (27)
  Eigen::MatrixXd m_w_um;                          ///< motion error under sensor 0, Eq. (27)
  Eigen::MatrixXd m1x_um, m2x_um, m3y_um, m4y_um;  ///< per-sensor motion errors, Eq. (2) form
  Eigen::MatrixXd m_wxe_um, m_wye_um;              ///< rotation terms, Eqs. (24), (26) (0 if off)
  Eigen::MatrixXd r1x_um, r2x_um, r3y_um, r4y_um;  ///< reference profiles, Eq. (9) per row/column
  bool rotation_corrected = true;
  std::string brief_report() const;
};

/// Runs Eqs. (10)-(27).  Throws std::invalid_argument on invalid options, mismatched matrix sizes
/// (naming the matrix), a grid too short for d, or non-finite readings.
TwoAxisResult separate_two_axis(const TwoAxisScan& scan, const TwoAxisOptions& opts);

}  // namespace errsep::core

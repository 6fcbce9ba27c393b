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
// Solvers.  TwoAxisSolver::joint (default) fits every reference reading of both scans in one
// least-squares system (displacement_joint.hpp: each reference piece's profile is a function of
// one coordinate shared by every row or column, and m is read in both scans) and states a
// per-point uncertainty of every output; TwoAxisSolver::row_by_row is the paper's path, Eq. (9)
// on each row and column separately with m from scan 1, kept for comparison (no uncertainty).
//
// Rotation correction, when it helps.  Eqs. (22)-(27) remove the roll/pitch terms m_wxe, m_wye
// but multiply the reference sensors' noise by the lever ratio (l_xw/l_xs = 5.5 for the paper's
// 165/30 mm).  RotationCorrection::automatic predicts the error of w's shape (w minus its mean:
// the constant is the gauge) with and without it from the joint estimate's covariance and the
// estimated rotation terms, and applies it only when the prediction falls:
//   with    E_on  = mean u²(w_on) − Var(mean w_on)
//   without E_off = mean u²(w_off) − Var(mean w_off) + B²,
//   B² = mean (b̂ − mean b̂)² − (mean u²(b̂) − Var(mean b̂)),  b = m_wxe + m_wye (0 if negative)
// Both figures are in the result (predicted_rms_on_um / _off_um).  With the row-by-row solver
// automatic means on (no covariance to predict from).  The prediction counts the noise only: a
// sensor drift puts into the rotation terms what a roll/pitch would, and the separation alone
// cannot tell them apart; the refine re-takes the decision with the drift its redundancy sees
// (displacement_refine.hpp, "Rotation correction").
//
// Grids: matrices are nx × ny with element (i, j) at (x_i, y_j).
#include <Eigen/Core>
#include <limits>
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

enum class TwoAxisSolver {
  joint,       ///< one least-squares system for every reading (default)
  row_by_row,  ///< the paper: Eq. (9) per row and column, m from scan 1
};
enum class RotationCorrection {
  on,         ///< Eqs. (22)-(27)
  off,        ///< Eqs. (20)-(21): m_w = m2_x + m4_y
  automatic,  ///< on when the predicted error of w falls (joint solver; see above)
};
const char* to_string(TwoAxisSolver s);
const char* to_string(RotationCorrection r);

struct TwoAxisOptions {
  double dx_mm = 5.0;              ///< sampling interval along x
  double dy_mm = 5.0;              ///< sampling interval along y
  double displacement_x_mm = 5.0;  ///< d for reference piece X (integer multiple of dx_mm)
  double displacement_y_mm = 5.0;  ///< d for reference piece Y (integer multiple of dy_mm)
  TwoAxisGeometry geometry;
  /// Apply Eqs. (22)-(27) (on), Eqs. (20)-(21): m_w = m2_x + m4_y (off, the paper's Fig. 22),
  /// or whichever predicts the smaller error of w (automatic).
  RotationCorrection rotation = RotationCorrection::automatic;
  TwoAxisSolver solver = TwoAxisSolver::joint;
  ChainJoin chain_join = ChainJoin::least_roughness;
  /// σ of one reading of sensor 0 (the workpiece sensor).  NaN: estimated from sensor 0's repeat
  /// in scan 2 when recorded, else taken equal to the reference sensors' σ̂ (said in the result).
  double workpiece_sigma_um = std::numeric_limits<double>::quiet_NaN();
  /// Standard uncertainty of each traverse d_x, d_y (independent); 0 = exact.
  double displacement_sigma_mm = 0.0;

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
  TwoAxisSolver solver = TwoAxisSolver::joint;
  RotationCorrection rotation_requested = RotationCorrection::automatic;

  // ---- joint solver only (empty / NaN for row_by_row) ----
  /// Standard uncertainties per point, same layout as the estimates (σ̂ and the traverse's u).
  Eigen::MatrixXd u_w_um, u_m_w_um, u_m1x_um, u_m2x_um, u_m3y_um, u_m4y_um, u_m_wxe_um, u_m_wye_um,
      u_r1x_um, u_r2x_um, u_r3y_um, u_r4y_um;
  double sigma_reference_um = std::numeric_limits<double>::quiet_NaN();  ///< σ̂ of sensors 1-4
  int dof_reference = 0;  ///< its degrees of freedom (the redundancy of the reference tracks)
  double sigma_workpiece_um = std::numeric_limits<double>::quiet_NaN();  ///< σ of sensor 0
  std::string sigma_workpiece_source;  ///< "given", "sensor 0 repeat (dof n)" or "assumed ..."
  /// Predicted rms error of w's shape with and without Eqs. (22)-(27) (see above).
  double predicted_rms_on_um = std::numeric_limits<double>::quiet_NaN();
  double predicted_rms_off_um = std::numeric_limits<double>::quiet_NaN();
  /// The terms of predicted_rms_off_um: the rotation terms' shape beyond their noise (B above)
  /// and the noise of that shape (√(mean u²(b̂) − Var(mean b̂))), µm.  The refine
  /// (displacement_refine.hpp) re-takes the automatic decision with them.
  double rotation_bias_um = std::numeric_limits<double>::quiet_NaN();
  double rotation_terms_noise_um = std::numeric_limits<double>::quiet_NaN();
  std::string rotation_note;  ///< the decision and both figures, one line
  std::string gauge;          ///< what the method cannot determine, said once
  double seconds = 0;         ///< time of the separation
  std::string brief_report() const;
};

/// Runs Eqs. (10)-(27).  Throws std::invalid_argument on invalid options, mismatched matrix sizes
/// (naming the matrix), a grid too short for d, or non-finite readings.
TwoAxisResult separate_two_axis(const TwoAxisScan& scan, const TwoAxisOptions& opts);

}  // namespace errsep::core

#pragma once
// Yaw of the x table in the two-axis displacement method (Haramiishi et al. 2024, section 2.2:
// "the proposed model cannot measure the rotation around the z-axis"; section 3.4: "increasing
// the number of sensors can also detect the yaw component").
//
// What yaw does.  A yaw ψ of the x table (about a vertical axis) moves the table point under a
// fixed sensor sideways, by ψ times the sensor's distance from the axis.  Height sensors see that
// only through the slope of the surface they read: sensor 0 reads w(x + δξ₀, y + δη₀) instead of
// w(x, y), sensors 1, 2 read r_k(x + δξ_k), with (s as in TwoAxisGeometry: along the line of
// sensors 2 → 1 → 0, sensor 2 at 0)
//
//   δξ_k = ψ·(s_k − s_axis),   δη₀ = ψ·(x − x_axis)   (the axis moves with the table and is under
//                                                      the sensor line at table position x_axis).
// Sensors 3, 4 and reference Y ride on the x table together and see none of it.
//
// Why Eqs. (10)-(27) cannot see it.  Per grid point the paper's reference sensors give two
// readings per scan for the unknowns ez_x and roll_x (both free per point), so the slope terms
// r_k′·δξ_k are absorbed into m1_x, m2_x as an apparent roll, and sensor 0's ∇w·δ into w itself;
// the only trace left is δξ_k·(r_k′(x + d) − r_k′(x)) between the two scans, i.e. ψ·r″·d, a
// second-order term.  At the paper's sizes (ψ of tens of µrad, slopes ≤ 0.3 µm/mm) the whole
// effect on w is ~10⁻³ µm, far below its sensor noise (0.16-0.29 µm): yaw matters for heights only
// with steep surfaces (an inclined face) or a poor stage (ψ of the order of a mrad).
//
// The sensors added here: a lateral pair, two displacement sensors a and b fixed to the base that
// read the side face of reference piece X at x positions X_a and X_b (b − a = the pair's base,
// a multiple of Δx).  Reference X carries the side face, so scan 2 reads it traversed by d like
// the top face (Eqs. 16-17).  Reading of lateral sensor k in scan q (q = 0, 1):
//
//   u_k,q(x, y) = g(x + X_k + q·d) + e_y(x, y) + ψ(x, y)·(X_k − (x − x_axis))
//
// g: the side face's lateral profile (one physical face: shared by every row y_j and both
// sensors), e_y: the table's lateral straightness at the sensors (free per point; it and the
// common part of the yaw term cancel in the four readings' deviations from their mean).
//
// Base model (no yaw): u = g + e_y + o_k + noise, o_b − o_a the pair's zero offset (the two
// sensors are never zeroed on the same point of the face).  It is over-determined: 4 readings
// per point, one e_y per point, one g shared by the whole grid and one offset, so the
// least-squares residual (dof = 3·nx·ny − G, G lattice values of g less its constant, plus the
// offset) is the redundancy in which yaw shows: the pair's difference ψ·(X_b − X_a), which no g
// can produce (g's inclination would also change the readings between scans by g′·d).  A
// constant yaw gives the same pattern as the zero offset (and as a sideways shift of reference X
// when it is traversed by d) and is not identifiable; it is the workpiece's placement on the
// table, a rotation of the whole map.  Yaw effect: ψ(x, y) = Σ c_kl P_k(u) P_l(v), Legendre in
// u = 2(x − x_0)/(x_max − x_0) − 1 and v likewise, k ≤ degree_x, l ≤ degree_y, (k, l) ≠ (0, 0);
// scored by an F-test against the base model, fitted by least squares (linear in c), standard
// uncertainties from σ̂.  When significant, the scans are corrected (sensor 0 by ∇ŵ·δ, sensors 1,
// 2 by r̂_k′·δξ_k, slopes from the current separation, a fixed-point iteration because ŵ
// improves with each correction) and Eqs. (10)-(27) run again.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "errsep/core/displacement_simulation.hpp"
#include "errsep/core/two_axis_displacement.hpp"

namespace errsep::core {

struct YawGeometry {
  double axis_s_mm = 0.0;     ///< yaw axis on the sensor line (s as TwoAxisGeometry; 0 = sensor 2)
  double axis_x_mm = 60.0;    ///< table position at which the yaw axis is under the sensor line
  double lateral_a_mm = 0.0;  ///< X_a, position of lateral sensor a along reference X
  double lateral_b_mm = 100.0;  ///< X_b; X_b − X_a must be a non-zero multiple of Δx
  bool is_valid(double dx_mm, std::string* why = nullptr) const;
};

/// Lateral pair readings, nx × ny like TwoAxisScan (scan 1 = _1, scan 2 = _2).
struct LateralPairScan {
  Eigen::MatrixXd ua_1_um, ua_2_um, ub_1_um, ub_2_um;
};

struct YawTruth {
  GridFn yaw_rad;     ///< ψ(x, y) of the x table (the y table's load moves with y)
  AxisFn side_um;     ///< g: lateral profile of reference X's side face
  GridFn lateral_um;  ///< e_y: lateral straightness of the x table at the lateral sensors
  double offset_a_um = 0.0, offset_b_um = 0.0;  ///< zero offsets of the lateral sensors
};

struct YawSimData {
  TwoAxisSimData two_axis;  ///< Eqs. (10)-(19) readings with the yaw's slope terms added
  LateralPairScan lateral;
  Eigen::MatrixXd yaw_rad;  ///< truth ψ(x_i, y_j)
};

/// simulate_two_axis plus yaw: the yaw terms are added to its readings exactly (the truth
/// functions evaluated at the shifted points, minus at the nominal ones; scan 2 with the nominal
/// d, so displacement_bias_mm and displacement_sigma_mm must be 0), and the lateral pair is read
/// with the eddy-current sensors' noise (own seeded stream; no drift).  Throws
/// std::invalid_argument for invalid options or missing truth functions.
YawSimData simulate_two_axis_yaw(const TwoAxisTruth& truth, const YawTruth& yaw,
                                 const TwoAxisSimOptions& opts, const YawGeometry& geometry);

struct YawRefineOptions {
  TwoAxisOptions separation;  ///< Eqs. (10)-(27) before and after
  YawGeometry geometry;
  int degree_x = 2;        ///< Legendre degrees of ψ along x
  int degree_y = 1;        ///< and along y
  double alpha = 0.01;     ///< significance of the F-test
  int iterations = 3;      ///< fixed-point iterations of the correction
  double rank_tol = 1e-9;  ///< relative singular value below which a direction is lost
  bool is_valid(std::string* why = nullptr) const;
};

struct TwoAxisYawResult {
  TwoAxisResult before;  ///< Eqs. (10)-(27) on the raw scans
  TwoAxisResult after;   ///< on the yaw-corrected scans (= before when yaw was not added)
  bool yaw_added = false;
  std::vector<std::string> parameter_names;  ///< c_<k>_<l>_urad, (k, l) ≠ (0, 0)
  Eigen::VectorXd parameters_urad, u_parameters_urad;
  Eigen::MatrixXd covariance_urad2;
  int identifiable = 0;
  double F = 0, p_value = 1;
  double rss_before_um2 = 0, rss_after_um2 = 0;  ///< lateral-pair residual, base and with yaw
  int dof_before = 0, dof_after = 0;
  double sigma_before_um = 0, sigma_after_um = 0;
  double rms_before_um = 0, rms_after_um = 0;  ///< RMS of the projected residual rows
  Eigen::MatrixXd yaw_rad;                     ///< ψ̂(x_i, y_j) (zero when not added)
  Eigen::VectorXd side_um;  ///< ĝ on its lattice, first point 0 (from the model finally chosen)
  std::string brief_report() const;
};

/// Fits the lateral pair, tests for yaw, corrects the scans and re-runs Eqs. (10)-(27).  Throws
/// std::invalid_argument for invalid options or matrices of the wrong size.
TwoAxisYawResult refine_two_axis_yaw(const TwoAxisScan& scan, const LateralPairScan& lateral,
                                     const YawRefineOptions& opts);

}  // namespace errsep::core

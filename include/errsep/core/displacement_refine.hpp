#pragma once
// Closing the loop for the two-axis displacement method (issue 16 item 4): the redundancy of the
// joint estimate (displacement_joint.hpp, displacement_residuals.hpp) drives the selection of the
// effects its model lacks (displacement_effects.hpp), and a step is taken only when it lowers the
// expected error of what the user gets, by the same rule as the four-sensor loop
// (step_decision.hpp).
//
// The redundant equations.  Per grid point the joint model leaves only the scan difference
// D_k = S k_2 − S k_1 of each reference sensor to test (the sum is taken by the motion, free per
// point): D_k = r_k(a + d) − r_k(a) repeats on every row (sensors 1, 2) or column (3, 4), so its
// residual is D_k minus its mean over the row/column group; sensor 0 read in both scans adds
// D_0 = S0_2 − S0_1 = offset + noise (one group).  These residuals are an orthogonal projection P
// of the readings, and the separation is linear in the readings, so an effect with parameters q
// and unit readings E (one TwoAxisScan per parameter) enters as
//   residual columns   P·E                    (what the redundancy sees of it)
//   sensitivities      D = −sep(E)            (what applying the correction changes in w, m_w)
// and the fit of q to the residuals is a weighted least-squares problem of a few columns
// (weights 1/(√2 σ̂) per sensor kind, σ̂ of the separation).  Its estimate is independent of the
// separation's (P is orthogonal to what the separation uses), so the refined u is
// refined_uncertainty(u_sep, D, C, q̂, applied).  P·E and D depend only on the grid, the scan
// order and the separation's options: the library computes them once (no data), and with them
// which effects the plan can identify at all (the smallest singular value of P·E relative to E).
//
// What the paper's plan (scan 2 runs the raster as scan 1) identifies: thermal drift (not linear
// in time: the scan difference varies from row to row) and a table tilt between the scans (only
// through sensor 0's repeat).  It cannot identify a linear drift of any sensor (the scan
// difference is the same constant at every point: absorbed by r's slope and by sensor 0's
// offset), nor an error of the traverse d or a yaw between the scans (functions of the piece's
// coordinate alone: absorbed by r; the traverse's u is in the separation's).  Running scan 2
// backwards (TwoAxisScanOrder::reverse_scan2) makes linear drift identifiable, but for sensors 3-4
// only through its fast part (below); running scan 2 y fastest (y_fastest_scan2) makes the
// offset between a point's two readings vary by ~n_x·n_y samples along rows and columns alike, so
// every sensor's drift is determined about as well (group_u_w_per_sigma states it per plan).
//
// Selection, forward (as refine.hpp): in each round every identifiable effect not yet taken
// (thermal once, the variant of its τ grid that fits best) is tested by the F-test of its columns
// added to those taken, with a Bonferroni correction over the variants tried; the best one below
// α is taken.  Then every taken effect is decided by decide_step on its parameters' block of the
// joint fit, one group of sensors at a time (sensor 0; reference X, sensors 1-2; reference Y,
// sensors 3-4), quantities w and m_w (gauge: their constant removed): applied, or detected and
// its fitted size added to u.  Why per group: with the raster x fastest, a reference Y track's
// groups (columns) are read within n_x samples, so a drift of sensors 3-4 is seen only through
// its fast part, while what it does to w comes from its slow part (the column means, absorbed by
// r_y): in the backward plan sensors 1-2 drift rates are determined ~25x better than 3-4's.
//
// What the data cannot separate (carried in u, said in not_identifiable).  On every plan but the
// paper's, the time between a point's two sensor-0 readings is affine in the grid indices, so
// sensor 0's drift is one direction of a table tilt (only sensor 0's repeat sees either): when
// one is taken, the other explanation of the same residual (the shift along the joint columns'
// null direction) moves w by what it would have done, and that goes into u.  A thermal drift's τ
// is not linear: every τ of the grid within the 95 % profile-likelihood set is refitted and the
// largest change of the thermal correction's w goes into u (the Gauss–Newton column alone left
// y fastest backwards covering 0.93 at σ 0.2, one run 0.08).
//
// Why thermal drift is rarely halved with scan 1 a raster (measured on scan 2 y fastest
// backwards, 20 seeds at σ 0.05/0.1/0.2: given the true τ and every group applied, 11/14/9 halved;
// with the drift on sensors 0-2 only, 15/16/16; on sensors 0, 3, 4 only, 1/6/4): a reference
// piece's redundancy compares its readings along one axis, and scan 1 x fastest (the paper)
// spreads a column (what sensors 3-4 compare) over only n_x samples, so sensors 3-4 see only scan
// 2's time variation, while a drift with τ below about one scan has mostly settled by then: their
// correction's u on w is 1.6-5.0 per µm of noise over the τ grid (group_u_w_per_sigma) while the
// drift moves w by ~5x the clean error.  Scan 1 along wrapped diagonals
// (TwoAxisScanOrder::diagonal_scan1) reads every row and column over the whole of scan 1: with
// scan 2 y fastest backwards, sensors 3-4's thermal correction is determined as well as 1-2's
// (0.33-1.07 per µm of noise), and the thermal drift was halved in 17/19/19 of 20 runs
// (tests/core/displacement_refine.cpp; linear drift 19/17/20, tilt 20/20/20, nothing applied on
// clean data).
//
// Rotation correction (RotationCorrection::automatic), re-taken here.  The separation decides
// Eqs. (22)-(27) on the noise alone (two_axis_displacement.hpp): the rotation terms
// b̂ = m_w(on) − m_w(off) = −(m_wxe + m_wye) are taken for a roll/pitch when their shape exceeds
// their noise.  A drift of a reference sensor puts the same into m3 − m4 (m1 − m2) as a pitch
// (roll) does, and Eqs. (24), (26) multiply it by the lever ratio (165/30 = 5.5); the redundancy
// sees only the drift's scan difference, the separation's sum of the two scans carries it into m.
// Measured on the diagonal plan (20 x 20, σ 0.1, thermal drift of sensors 3-4, 1.5-3σ, τ 0.3-3
// scans, no rotation; seeds 1601-1620): the separation switched the correction on in 16/20, w's
// error median 3.4 um against 0.48 off; the rotation terms' shape 0.9-6.2 um against a per-point
// u of 1.3-1.5 um (their own significance cannot tell), σ̂ of the reference tracks 0.99-1.10 of
// the truth (nor can the misfit).  What tells is the effect library: the refine explains the
// residual by the effects taken, by each family not taken added (every τ of the thermal grid), and
// a taken thermal drift at every τ of its grid; per explanation a least-squares fit q̂ (covariance
// C) of its columns gives, with D_r = d_w of rotation off (r = 0) and on (1), G = D_1 − D_0 (what
// the artefacts put into b̂), shapes (constant removed) and mean squares over the points:
//   E_on  = noise_on  + L_1,    E_off = noise_off + L_0 + R,
//   L_r   = mean diag(D_r C D_rᵀ) for the effects taken (the refine corrects them) +
//           max(0, ‖D_r q̂‖² − mean diag(D_r C D_rᵀ)) for an effect not taken (left in w),
//   R     = max(0, ‖b̂ − G q̂‖² − noise of b̂'s shape − mean diag(G C Gᵀ)): the rotation share,
// noise_on, noise_off the separation's predictions without the rotation bias.  The explanations
// are weighted by Akaike (χ² of the residual + 2 per parameter, a τ from the grid one more,
// relative likelihood exp(−ΔAIC/2)), so that an effect too weak for the F-test still counts by how
// much better it fits (seed 1615: ΔAIC −9, it moves w by 3.4 um with the correction, 0.2 without).
// The correction is on when the weighted E_on < E_off and every explanation of relative likelihood
// ≥ 0.05 agrees (an artefact taken for a rotation is multiplied by the lever ratio, a rotation
// taken for an artefact is not).  The refined u of the chosen branch carries the likeliest
// explanation's L of the effects not taken, and off its R (the rotation it leaves in w).  Figures
// (tests/core/two_axis_rotation_decision.cpp, 20 seeds per cell at σ 0.05/0.1/0.2): thermal drift
// of sensors 3-4 switched on 11/6/12 -> 0/1/2, refined w error median 0.45/0.28/1.81 -> 0.10/0.24/
// 0.45 um; on every sensor 19/18/18 -> 0/0/0; a real roll/pitch of 1000σ µrad kept on 20/19/20.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "errsep/core/displacement_effects.hpp"
#include "errsep/core/step_decision.hpp"
#include "errsep/core/two_axis_displacement.hpp"

namespace errsep::core {

struct DisplacementRefineOptions {
  double alpha = 0.01;  ///< significance of a step's F-test (after Bonferroni)
  /// Time constants tried for the thermal drift, as multiples of one scan's duration.
  std::vector<double> thermal_tau_scans = {0.2, 0.3, 0.45, 0.7, 1.0, 1.5, 2.2, 3.3, 5.0};
  /// An effect is identifiable when the smallest singular value of its residual columns, relative
  /// to that of its scan-difference columns, is above this.
  double identifiable_tolerance = 1e-3;
  /// A sensor pair's correction is called poorly determined on a plan (a line in
  /// not_identifiable; nothing else changes) when what it adds to u(w) per µm of noise
  /// (group_u_w_per_sigma) is more than this many times the other pair's.
  double poorly_determined_ratio = 2.0;
  StepDecisionOptions decision;
  bool is_valid(std::string* why = nullptr) const;
};

/// One effect of the library on one grid and scan order.
struct DisplacementEffect {
  std::string family;                   ///< "drift", "thermal", "tilt"
  std::string name;                     ///< e.g. "thermal (tau = 312 s)"
  std::vector<std::string> parameters;  ///< e.g. "a0_um" … "a4_um"
  /// Parameter groups decided on their own (drift and thermal: sensor 0, sensors 1-2, 3-4).
  std::vector<std::vector<int>> groups;
  DisplacementDisturbance unit(Eigen::Index parameter) const;  ///< one unit parameter
  double tau_s = 0;                                            ///< thermal only
  Eigen::MatrixXd residual_columns;  ///< P·E: residual rows (see library) × parameters, µm
  /// −sep(E) for w and m_w, nx·ny (column major) × parameters; [0] rotation off, [1] on.
  Eigen::MatrixXd d_w[2], d_m_w[2];
  bool identifiable = false;
  double relative_singular_value = 0;
  /// Per group (identifiable effects only): the RMS standard uncertainty its fitted correction
  /// adds to w (constant removed, rotation off) per µm of reading noise, every sensor at one σ.
  /// Computed from the plan alone: a correction can halve an effect's error of w only when the
  /// effect moves w by several times this·σ.
  std::vector<double> group_u_w_per_sigma;
};

struct DisplacementEffectLibrary {
  int nx = 0, ny = 0;
  bool s0_repeat = false;  ///< sensor 0 read in scan 2 (its repeat is in the residual rows)
  TwoAxisScanOrder order;
  std::vector<DisplacementEffect> effects;
  /// What this plan cannot identify, or determines poorly for one pair of sensors (their
  /// correction rarely worth applying), one line each (said once, not per run).
  std::vector<std::string> not_identifiable;
};

/// The library for scans on this grid (x_mm, y_mm) in this order.  Throws std::invalid_argument
/// for invalid options.
DisplacementEffectLibrary make_displacement_effect_library(const Eigen::VectorXd& x_mm,
                                                           const Eigen::VectorXd& y_mm,
                                                           bool s0_repeat,
                                                           const TwoAxisScanOrder& order,
                                                           const TwoAxisOptions& separation,
                                                           const DisplacementRefineOptions& o = {});

/// The residual rows of the redundant equations, scan differences minus their group means (the
/// sensor 1, 2, 3, 4 groups, then sensor 0's when repeated), µm.
Eigen::VectorXd displacement_redundancy_residual(const TwoAxisScan& scan);

struct DisplacementRefineStep {
  std::string effect;
  std::vector<std::string> names;
  Eigen::VectorXd value, u;  ///< fitted parameters and their standard uncertainties
  double F = 0, p_value = 1;
  bool applied = false;
  StepDecision decision;
  std::string line;  ///< describe_decision's line
};

struct DisplacementRefineResult {
  TwoAxisResult base;     ///< the separation of the readings as measured
  TwoAxisResult refined;  ///< of the corrected readings; u_w_um, u_m_w_um the refined ones
  std::vector<DisplacementRefineStep> steps;  ///< effects taken (applied or detected)
  /// The library's lines (what the plan cannot identify, said once), then this run's: two effects
  /// the data cannot separate, the range of thermal τ the data do not reject (both carried in u).
  std::vector<std::string> not_identifiable;
  double sigma_scale = 1;  ///< residual variance after the fit over σ̂² (≈ 1 when the model fits)
  bool applied_any() const;
  std::string brief_report() const;
};

/// Separation, selection and decision (see above).  With RotationCorrection::automatic the
/// rotation correction is re-taken with the effects the redundancy sees (above), and the refined
/// separation uses that decision (base keeps the separation's own); on or off are kept as given.
/// Throws std::invalid_argument when the scan does not match the library's grid or sensor 0 repeat,
/// or the options are invalid.
DisplacementRefineResult refine_two_axis(const TwoAxisScan& scan, const TwoAxisOptions& separation,
                                         const DisplacementEffectLibrary& library,
                                         const DisplacementRefineOptions& o = {});

}  // namespace errsep::core

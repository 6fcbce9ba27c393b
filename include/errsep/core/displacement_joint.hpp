#pragma once
// The displacement method's joint least-squares estimate (Haramiishi et al. 2024, Eqs. 2-4 and
// 11-19 read as one linear system) and the covariance of what it estimates.
//
// A reference track is what one reference sensor reads of one reference piece in both scans:
//   S_1(a_i, b_j) = r(a_i) + m(a_i, b_j)          (2), (11)-(14)
//   S_2(a_i, b_j) = r(a_i + d) + m(a_i, b_j)      (3), (16)-(19),   d = p·Δa
// a is the piece's coordinate (x for reference X, sensors 1 and 2; y for reference Y, sensors 3
// and 4), b the other one (one column on one axis).  r depends on a alone (the piece is one rigid
// body read by sensors fixed to the base: displacement_residuals.hpp), the motion m is free at
// every grid point.  Unknowns: m (n_a·n_b) and r(a_0 … a_{n_a−1+p}); readings 2·n_a·n_b.  The
// gauge: r + c_{i mod p}, m − c_{i mod p} leave every reading unchanged, so the p values
// r(a_0 … a_{p−1}) are fixed at 0 (the paper's initial value of Eq. 9) and are not unknowns.
// Redundancy: n_a(n_b − 1) per track (none on one axis: Eqs. 1-3 are exactly determined).
//
// Row by row (the paper, separate_two_axis with TwoAxisSolver::row_by_row) solves Eq. (9) on each
// row b_j on its own and takes m from scan 1 only; the joint estimate uses every row for the one
// r and both scans for m: m̂(a_i, b_j) = ½(S_1 − r̂(a_i) + S_2 − r̂(a_i + d)).  At the paper's noise
// on a 25 × 25 grid this cuts the w error about 4× (tests/core/displacement_joint.cpp).
//
// Every track is one block of one sparse system solved by SparseLeastSquares (the blocks share no
// unknown: the motion at sensor 1 and at sensor 2 differ by the roll, free per point).  The
// workpiece sensor's readings S0 = w + m_w (Eq. 10, read once or twice) are not in the system:
// w is free at every point, so its normal equation is w = mean(S0) − m_w and the Schur complement
// of the w block leaves the normal equations of the tracks exactly as they are without S0; the
// estimate of w and its variance (σ0²/n0 + Var(m̂_w)) follow in closed form.
//
// Units: r, m in µm; the traverse sensitivity in µm per mm of error in d.
#include <Eigen/Core>
#include <limits>
#include <string>
#include <vector>

#include "errsep/core/displacement_method.hpp"
#include "errsep/core/sparse_least_squares.hpp"

namespace errsep::core {

/// One reference sensor's readings, n_a × n_b (rows along the piece).
struct ReferenceTrackScan {
  Eigen::MatrixXd scan1_um, scan2_um;
  int step = 1;             ///< p = d / Δa
  double spacing_mm = 5.0;  ///< Δa
};

struct ReferenceTrackFit {
  Eigen::VectorXd r_um;  ///< r(a_0 … a_{n_a−1+p}), r(a_0 … a_{p−1}) = 0 (the gauge)
  Eigen::MatrixXd m_um;  ///< n_a × n_b
  /// Diagonal of (AᵀA)⁻¹ for r and m: the variance per unit reading variance σ².
  Eigen::VectorXd var_r;
  Eigen::MatrixXd var_m;
  /// Change of r̂ and m̂ per mm of error in the traverse d (the scan-2 readings then see
  /// r(a + d + δ) ≈ r(a + d) + δ·r′(a + d); r′ from r̂ by central differences).
  Eigen::VectorXd dr_dd_um_per_mm;
  Eigen::MatrixXd dm_dd_um_per_mm;
  double rss_um2 = 0;  ///< sum of squared residuals of the track's 2·n_a·n_b readings
  int dof = 0;         ///< n_a(n_b − 1)
};

struct JointReferenceFit {
  std::vector<ReferenceTrackFit> tracks;
  /// gᵀ(AᵀA)⁻¹g for each requested functional g of the motion errors (see fit_reference_tracks).
  std::vector<double> functional_var;
  SparseLeastSquaresStats stats;
  double seconds = 0;  ///< whole fit, assembly to covariance
};

/// A linear functional of the motion errors: one n_a × n_b weight matrix per track (empty = 0).
using MotionFunctional = std::vector<Eigen::MatrixXd>;

/// Fits every track in one sparse system (see above).  Throws std::invalid_argument on unequal
/// scan sizes, a track not longer than its step, or non-finite readings (naming the track by its
/// index), std::runtime_error if the factorisation fails.
JointReferenceFit fit_reference_tracks(const std::vector<ReferenceTrackScan>& tracks,
                                       const std::vector<MotionFunctional>& functionals = {});

/// One-axis result with per-point standard uncertainties (the joint estimate, Eqs. 1-9).
struct OneAxisJointResult {
  DisplacementResult estimate;             ///< r, m, w (w from the mean of the workpiece readings)
  Eigen::VectorXd u_r_um, u_m_um, u_w_um;  ///< empty when no σ is known (see sigma_source)
  double sigma_um = std::numeric_limits<double>::quiet_NaN();  ///< σ of one reading used
  std::string sigma_source;  ///< where σ came from, or why there is no uncertainty
  int sigma_dof = 0;         ///< dof of σ̂ (0: given)
  std::string gauge;         ///< what the method cannot determine, said once
};

/// The one-axis joint estimate: r and m as Eq. (9) (exactly determined), w from S1_1 and, when
/// given (non-empty), S1_2.  σ of a reading: opts.reading_sigma_um when finite; else σ̂ from the
/// workpiece repeat S1_2 − S1_1 (sensors 1 and 2 taken as equally noisy, said in sigma_source);
/// else no uncertainty.  u includes opts.displacement_sigma_mm's contribution.  Throws as
/// separate_displacement.
OneAxisJointResult separate_displacement_joint(const Eigen::VectorXd& s1_first_um,
                                               const Eigen::VectorXd& s2_first_um,
                                               const Eigen::VectorXd& s2_second_um,
                                               const Eigen::VectorXd& s1_second_um,
                                               const DisplacementOptions& opts);

}  // namespace errsep::core

#pragma once
// What the displacement method (Haramiishi et al. 2024) measures more than once, the residual of
// each such redundant equation, the noise level it implies and whether it is white.
//
// Counting, one axis (Eqs. 1-3; n samples x_0..x_{n-1}, d = p·Δx).  Readings: S1_1, S2_1, S2_2,
// 3n.  Unknowns: w(x_k) and m(x_k), n each, and r at x_0..x_{n-1+p} (scan 2 reads r p samples
// beyond the range), n + p; r's p chain constants trade with m and w (r + c_{k mod p},
// m − c_{k mod p}, w + c_{k mod p} leave every reading unchanged) and are not identifiable.  3n
// readings for 3n identifiable values: the method as printed is exactly determined and leaves
// no residual at all.  In particular the overlap of the two reference scans (r(x_k) is read in
// scan 1 at x_k and in scan 2 at x_{k-p}) is not redundant: each of the two readings brings its
// own unknown m (m(x_k), m(x_{k-p})), and the overlap is exactly what Eq. (9) uses up.  What is
// redundant comes from readings beyond Eqs. (1)-(3):
//
//   workpiece repeat   sensor 1 also read during scan 2 (errsep-scan records it): the workpiece
//                      is not traversed, so Eq. (1) holds in scan 2 as well and
//                        S1_2(x) − S1_1(x) = 0                                     (1) twice
//                      up to a zero offset between the scans (one fitted constant): n equations,
//                      dof n − 1.  It tests what Eqs. (2) and (3) assume and cannot check
//                      themselves, that the table's motion error m(x) repeats between the scans
//                      (a table that moves between or during the scans shows here; the reference
//                      sensor sees the same motion and turns it into an error of r that
//                      accumulates through Eq. 9).  The offset is reported with its standard
//                      uncertainty: a sensor-1 zero shift is harmless, a table shift is not, and
//                      the data cannot tell them apart: a table that rose by c between the
//                      scans adds c to every difference of Eq. (4), so r (and w) take a tilt of
//                      c per sampling interval.
//   repeated runs      R >= 2 runs of the whole measurement (the paper repeats its experiment N
//                      times, Eq. 29): every reading is the same equation R times, residual =
//                      reading − its mean over the runs, dof n(R − 1) per channel.  The
//                      separation then runs on the mean of the runs.
//
// Two axes (Eqs. 10-19).  Per grid point and scan the reference sensors give 4 readings; the
// motion errors m1_x, m2_x, m3_y, m4_y are free per point (the x table's roll depends on where
// the y table's load is, Fig. 20, and so on), so per point and sensor only the difference of the
// two scans, Eqs. (16)-(11) etc., says anything about r:
//   D_k(x_i, y_j) = S k_2 − S k_1 = r k(x_i + d) − r k(x_i)   k = 1, 2          (4) from (11),(16)
//   D_k(x_i, y_j) = r k(y_j + d) − r k(y_j)                     k = 3, 4          (4) from
//   (13),(18)
// The paper writes r1_x(x, y), but reference piece X is one physical piece fixed to the x table
// and read by sensors fixed to the base: moving the y table does not change what sensors 1 and 2
// see of it, so r1_x and r2_x are functions of x alone, and likewise r3_y, r4_y of y alone.  Each
// row y_j is a repetition of Eq. (4) along x: nx·ny equations for the nx unknown first
// differences of each of r1_x, r2_x (dof nx(ny − 1) each), and ny·nx for r3_y, r4_y (dof ny(nx − 1)
// each).  Residual = D_k minus its mean over the rows (sensors 1, 2) or columns (3, 4), the
// least-squares fit of the shared first differences.  This is exactly the residual of the joint
// estimate that separate_two_axis uses by default (displacement_joint.hpp: per reading ∓(D − D̄)/2,
// the same σ̂ and dof; tests/core/displacement_joint.cpp), which cuts the w error at the paper's
// noise about 4x against the paper's row-by-row Eq. (9) (TwoAxisSolver::row_by_row, which does
// not use this redundancy); this residual is the test of the assumption the joint estimate rests
// on (one profile per reference piece).  Sensor 0 read during scan 2 as
// well (optional) gives the workpiece repeat of Eq. (10), dof nx·ny − 1; repeated runs as above.
// The sensor pairs 1-2 and 3-4 are not redundant once roll and pitch are corrected (Eqs. 22-27):
// their difference per point is the roll (pitch), free per point.
//
// What these residuals cannot see (they are exactly zero for it): a constant or linear-in-time
// zero drift (it adds the same amount to every D_k and every S1_2 − S1_1, so it is a constant of
// the group fit; it biases r by a slope, indistinguishable from r's own slope), a gain error that
// is the same in both scans (it scales r k(x + d) − r k(x) alike on every row), an error in the
// traverse d (r k(x + d + δ) − r k(x) is again the same on every row), and, on one axis, a drift
// of the reference sensor alone.  Yaw of the x table shows only at second order (ψ·r″·d);
// the lateral sensor pair of two_axis_yaw.hpp sees it.  What they do see: a drift that is not
// linear in time (a thermal transient: the paper's eddy-current sensors drift by 0.5 µm over 10
// min, Fig. 14), a table motion that does not repeat between the scans, a gain that changes
// between the scans, anything local in time (a knock, dust).
//
// Noise model of the residuals: independent, identically distributed reading noise σ per
// sensor kind; a difference of two readings has variance 2σ² (the run means of R runs: σ²/R).
// Every family's model is a set of group constants, so its residual is an orthogonal projection of
// white noise and σ̂² = RSS / (c·dof) is unbiased for the reading variance σ² (c: the variance
// factor above); its confidence interval follows χ²_dof.  The whiteness verdict is
// test_projected_whiteness (residual_analysis.hpp) on the residuals in time order, the five
// statistics of the four-sensor loop calibrated by Monte-Carlo draws of the same projection.
//
// Time order: one axis, both scans run in increasing x (the order of the rows); two axes, the
// raster x fastest, then y (simulate_two_axis), unless reading times are given.
//
// Reading of the paper.  It writes sensor 1 (one axis) and sensor 0 (two axes) only for scan 1
// (Eqs. 1, 10); S1_2 and S0_2 are errsep's, the same equations read again in scan 2.  Eq. (19)
// is printed "S42(x, y) = r4y(x, y + d) + m4y(x, y)", read as S4_2 = r4_y(x, y + d) + m4_y as
// Eqs. (16)-(18).  Eq. (28) prints the sum of Eq. (9) with a minus sign; read as Eq. (9) plus the
// accumulated errors Σδ, which is what the residuals here estimate σ of.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "errsep/core/residual_analysis.hpp"
#include "errsep/core/two_axis_displacement.hpp"

namespace errsep::core {

struct DisplacementResidualOptions {
  /// lags, Monte-Carlo draws, α, seed.  999 draws: with up to three families each is tested at
  /// α/3 (Bonferroni), and the combined Monte-Carlo p-value cannot go below 1/(draws + 1), nor
  /// much below the rank the draws' own extremes leave it (with 499 draws the paper-sized thermal
  /// drift of tests/core/displacement_residuals.cpp came out at p = 0.002-0.004 against α/2 =
  /// 0.005, and was missed in 1 of 5 seeds; with 999 at 0.001 in 5 of 5).
  ResidualAnalysisOptions whiteness = [] {
    ResidualAnalysisOptions w;
    w.mc_samples = 999;
    return w;
  }();
  double confidence = 0.95;  ///< level of the σ̂ interval
  /// Also refuses draws too few to reject at α/3: (mc_samples + 1)·α/3 must exceed 1.
  bool is_valid(std::string* why = nullptr) const;
};

/// One sensor's redundant equations in a family, in the family's time order.
struct ResidualChannel {
  std::string name;               ///< what the equations compare, e.g. "s1_scan2 - s1_scan1"
  int sensor = 0;                 ///< the paper's sensor number
  int scan = 0;                   ///< 1 or 2 for a reading of one scan (repeated runs), else 0
  Eigen::VectorXd value_um;       ///< the redundant quantity, one per equation
  Eigen::VectorXd residual_um;    ///< value minus the least-squares fit of its group constants
  std::vector<int> group;         ///< group (shared unknown) of each equation
  Eigen::VectorXd group_mean_um;  ///< the fitted constant of each group
  double variance_factor = 1.0;   ///< noise variance of one value over a reading's σ²
  int dof = 0;                    ///< equations − groups
  double rss_um2 = 0;
  double sigma_um = 0;  ///< σ̂ of one reading, sqrt(RSS / (variance_factor · dof)); 0 if dof = 0
};

enum class RedundancyKind {
  reference_pieces,  ///< two axes: Eq. (4) repeated on every row (sensors 1, 2) / column (3, 4)
  workpiece_repeat,  ///< Eq. (1) / (10) in both scans
  repeated_runs,     ///< the whole measurement R times
};

const char* to_string(RedundancyKind k);

/// Channels observed at the same instants, tested together for whiteness.
struct RedundancyFamily {
  RedundancyKind kind = RedundancyKind::reference_pieces;
  std::string equation;  ///< what is redundant and why, with the paper's equation numbers
  std::vector<ResidualChannel> channels;
  Eigen::VectorXd x_mm, y_mm;  ///< position of each equation (y = 0 on one axis), time order
  Eigen::VectorXi run;         ///< run (1-based) of each equation; 0 when runs were averaged
  int equations = 0;           ///< over all channels
  int dof = 0;                 ///< over all channels
  double rss_um2 = 0;
  double sigma_um = 0;  ///< pooled σ̂ of one reading, sqrt(Σ RSS / Σ c·dof)
  double sigma_low_um = 0, sigma_high_um = 0;  ///< its χ² confidence interval
  WhitenessTest whiteness;                ///< of all channels together (local window: see local_*)
  double local_x_mm = 0, local_y_mm = 0;  ///< position at the centre of the local-excess window
  int local_instants = 0;                 ///< that window's length in instants
  Eigen::VectorXd periodogram_power;      ///< along time, frequencies k/L, k = 1..L/2
  /// One line: kind, dof, σ̂ with interval, whiteness verdict with p-values.
  std::string brief_report() const;
};

struct DisplacementResiduals {
  std::vector<RedundancyFamily> families;  ///< empty: nothing redundant in the given readings
  int runs = 1;
  int dof = 0;  ///< over all families
  /// Every family white at α / (number of families) (Bonferroni over the families); true when
  /// there is nothing to test.
  bool white = true;
  double alpha = 0.01;
  std::string note;  ///< what could not be tested and why (e.g. exactly determined)
  /// Several lines: the overall verdict, then one per family.
  std::string brief_report() const;
};

/// One run of the one-axis measurement; s1_2_um (workpiece sensor during scan 2) may be empty.
struct OneAxisRun {
  Eigen::VectorXd s1_1_um, s2_1_um, s2_2_um, s1_2_um;
};

/// Mean of the runs, reading by reading (what the separation then uses).  Throws
/// std::invalid_argument when there are no runs or their lengths differ (naming the run).
OneAxisRun mean_of_runs(const std::vector<OneAxisRun>& runs);
/// Two axes: the same for the nine (or ten, with s0_2_um) reading matrices.
TwoAxisScan mean_of_runs(const std::vector<TwoAxisScan>& runs);

/// Residuals of the one-axis measurement (runs equal in length to x_mm, positions uniform and in
/// scan order).  Families: workpiece repeat (when every run has s1_2_um), repeated runs (R >= 2).
/// With neither, no family and a note that Eqs. (1)-(3) are exactly determined.  Throws
/// std::invalid_argument on invalid options, mismatched lengths or non-finite readings.
DisplacementResiduals displacement_residuals_one_axis(const Eigen::VectorXd& x_mm,
                                                      const std::vector<OneAxisRun>& runs,
                                                      const DisplacementResidualOptions& o = {});

/// Residuals of the two-axis measurement: reference pieces (always), workpiece repeat (when every
/// run has s0_2_um), repeated runs (R >= 2).  `time_order` (nx × ny, may be empty): any quantity
/// increasing with the time at which scan 1 read the point (scan 2 repeats the raster); empty
/// means x fastest, then y.  Throws std::invalid_argument as above.
DisplacementResiduals displacement_residuals_two_axis(const std::vector<TwoAxisScan>& runs,
                                                      const DisplacementResidualOptions& o = {},
                                                      const Eigen::MatrixXd& time_order = {});

}  // namespace errsep::core

#pragma once
// Closing the loop for the one-axis displacement method (issue 16 item 4; Haramiishi et al. 2024,
// Eqs. 1-9), the loop of service::DisplacementPipeline.  The two-axis loop is
// displacement_refine.hpp; this one shares its rule (step_decision.hpp) and its reading of
// what a plan identifies.
//
// The redundancy.  Eqs. (1)-(3) are exactly determined: the reference sensor 2 read in both scans
// gives r and m and leaves nothing to test.  The workpiece sensor 1 read in both scans (S1_2, as
// errsep-scan records it) repeats w + m, so D_1 = S1_2 − S1_1 minus its mean (one offset between
// the scans is allowed, as the joint estimate's σ̂) is the only residual: n − 1 rows.  An effect
// of sensor 1 with unit readings E(t) enters as the residual column P·(E(t_2) − E(t_1)), its
// correction changes w by −½(E(t_1) + E(t_2)) and leaves r and m alone.
//
// What a plan identifies.  Scan 2 in the order of scan 1 (the paper, errsep-scan) reads every
// point the same time after its first reading: a linear drift of sensor 1 is one constant in D_1
// (absorbed by the offset); a thermal drift (not linear in time) shows.  Scan 2 backwards shows
// both.  Nothing shows an effect of the reference sensor 2: a drift or thermal drift of it goes
// into r and m and from m into w.  When sensor 1's effect is detected, the same effect on sensor
// 2 is suspected (the sensors sit in one fixture and warm together) but not identifiable: u of w
// and m is widened by what it would do at the fitted size, and the result says so.
//
// Times: the recorded reading times (raw_displacement.csv's t_scan1_s, t_scan2_s), else equal
// steps in the order the options name (the paper's by default; said in the result).
#include <Eigen/Core>
#include <string>
#include <vector>

#include "errsep/core/displacement_joint.hpp"
#include "errsep/core/displacement_refine.hpp"
#include "errsep/core/displacement_scan_order.hpp"
#include "errsep/core/step_decision.hpp"

namespace errsep::core {

/// The two-axis loop's options (alpha, the τ grid, the decision rule) with the one-axis
/// identifiability threshold: an effect is identifiable when its residual column keeps more than
/// 5 % of its scan difference's norm, on the plan's nominal times (equal steps, in the order the
/// recorded times show): a paper-order plan's timing jitter leaves ~3e-3–7e-3 of a linear drift
/// in recorded simulator scans, and up to 5 % on a loaded machine, which must not make the
/// plan's identifiability change from run to run.
struct OneAxisRefineOptions : DisplacementRefineOptions {
  OneAxisRefineOptions() { identifiable_tolerance = 0.05; }
  /// The order scan 2 ran in, for the reading times modelled when none are recorded (equal
  /// steps, scan 2 after scan 1; recorded times say it themselves).
  DisplacementScanOrder scan2_order = DisplacementScanOrder::forward;
};

/// One row of the refine's account: an effect taken (applied or detected) or one the plan cannot
/// identify.
struct OneAxisRefineStep {
  std::string effect;                 ///< e.g. "drift of sensor 1", "thermal (tau = 40 s)"
  std::string decision;               ///< "applied", "detected, not applied", "not identifiable"
  std::vector<std::string> names;     ///< parameter names
  Eigen::VectorXd value, u;           ///< fitted parameters and their standard uncertainties
  double F = 0, p_value = 1;          ///< the F-test that took it
  double rms_w_change_um = 0;         ///< what the correction changes in w (RMS, gauge removed)
  double rms_w_error_left_um = 0;     ///< estimated error of w without it (decision's bias)
  double rms_w_error_applied_um = 0;  ///< added to u(w) by applying it (its covariance)
  double rms_u_w_added_um = 0;        ///< RMS of what the step adds to u(w) in the result
  std::string line;                   ///< one line for a report
};

struct OneAxisRefineResult {
  OneAxisJointResult base;     ///< the separation of the readings as recorded
  OneAxisJointResult refined;  ///< of the corrected readings; u_w_um, u_m_um the refined ones
  std::vector<OneAxisRefineStep> steps;
  std::vector<std::string> notes;  ///< plan and times (what was assumed), said once
  bool applied_any() const;
  std::string brief_report() const;
};

/// Separation, selection (forward, ranked as displacement_refine.hpp), decision and the refined
/// u.  t1_s, t2_s: the times of the readings of scan 1 and 2 (empty: equal steps, paper order).
/// Without S1_2 (empty) nothing is identifiable: the result is the separation with that said.
/// Throws std::invalid_argument for invalid options or sizes.
OneAxisRefineResult refine_one_axis(const Eigen::VectorXd& s1_1_um, const Eigen::VectorXd& s2_1_um,
                                    const Eigen::VectorXd& s2_2_um, const Eigen::VectorXd& s1_2_um,
                                    const Eigen::VectorXd& t1_s, const Eigen::VectorXd& t2_s,
                                    const DisplacementOptions& separation,
                                    const OneAxisRefineOptions& o = {});

}  // namespace errsep::core

#pragma once
// Compensation tables from a measured straightness error (pure computation; the controllers' file
// formats are written by errsep/io/cnc/).
//
// Sign convention (once, for every table):
//   error        e(p) = actual - commanded position of the OUTPUT axis while the INPUT axis is at
//                       machine position p (ISO 230-1 E<output><input>); from the separated S(x)
//                       through the configured MachineAxes: e(p(x)) = reading_sign * S(x).
//   compensation c(p) = -e(p), added by the controller to the output axis command, so that
//                       actual = commanded + c + e = commanded.
// Tables hold c in um at machine positions; writers convert to the controller's unit.
//
// A line is removed from e first (the end-point line by default): the slope of S relative to the
// other axis is set by how the artefact was aligned, not by the machine, and would otherwise be
// "compensated" as a squareness error that was never measured.  With the end-point line removed,
// c is 0 at both ends of the measured range, so a controller that holds the end values outside a
// table applies nothing outside the measurement.
//
// A table represents the measurement only inside the measured range: its nodes lie in
// [first, last] measured position (no extrapolated node), and its own interpolation error against
// the measured profile (TableAccuracy) is reported with it.
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "errsep/core/iso230.hpp"
#include "errsep/core/machine_axes.hpp"

namespace errsep::core {

struct CompensationOptions {
  /// Line removed from the error before tabulating (nullopt: keep S as it is).
  std::optional<ReferenceLine> remove_line = ReferenceLine::end_points;
};

/// The compensation c = -e as a function of machine position, at the measured samples; linear in
/// between (the measurement's own resolution), undefined outside [first_mm, last_mm].
struct CompensationProfile {
  MachineAxes axes;
  std::vector<double> position_mm;  ///< machine positions of the input axis, increasing
  std::vector<double> comp_um;      ///< c at those positions
  std::vector<double> u_um;         ///< standard uncertainty of c (that of S), or empty
  std::optional<ReferenceLine> removed_line;

  double first_mm() const { return position_mm.front(); }
  double last_mm() const { return position_mm.back(); }
  /// c at machine position p: linear between samples, the end value held outside.
  double at(double p_mm) const;
};

/// The profile of a separated straightness S(x) (x from the scan start, strictly increasing; u_S
/// per point or empty).  Throws std::invalid_argument (bad axes, sizes, non-finite values).
CompensationProfile compensation_profile(const std::vector<double>& x_mm,
                                         const std::vector<double>& s_um,
                                         const std::vector<double>& u_s_um, const MachineAxes& axes,
                                         const CompensationOptions& opts = {});

/// A table as a controller holds it: nodes at machine positions (increasing) and values, linear
/// between nodes, the end values held outside (what the CEC, lincurve, cross-compensation and TNC
/// tables do).
struct CompensationTable {
  std::vector<double> position_mm;
  std::vector<double> comp_um;
  double step_mm = 0;  ///< node spacing of a uniform table; 0 for free breakpoints
  std::size_t points() const { return position_mm.size(); }
  double at(double p_mm) const;
};

/// How well a table represents the measurement: |table - profile| over the measured range.  Both
/// are piecewise linear, so the largest difference lies at a sample or at a node; both are
/// evaluated.  RMS over the measured samples.  `extra_um` is added to the maximum for what is not
/// piecewise linear in the controller (e.g. LinuxCNC's truncation to whole counts).
struct TableAccuracy {
  double max_um = 0;
  double rms_um = 0;
  double position_of_max_mm = 0;
};
TableAccuracy table_accuracy(const CompensationProfile& profile, const CompensationTable& table,
                             double extra_um = 0.0);

struct UniformTableOptions {
  /// The controller's point limit (0 = none), e.g. Sinumerik MD18342 $MN_MM_CEC_MAX_POINTS.
  std::size_t max_points = 0;
  /// 0: chosen from the data (the samples themselves when they are uniform and fit the limit,
  /// else the spacing with the smallest interpolation error that fits); > 0: a step that must
  /// divide the measured span (the last node is the last measured position).
  double step_mm = 0;
  bool is_valid(std::string* why) const;
};

/// Uniform table over exactly the measured range.  Throws std::invalid_argument with an actionable
/// message (a step that does not divide the span, more points than the limit).
CompensationTable make_uniform_table(const CompensationProfile& profile,
                                     const UniformTableOptions& opts = {});

struct BreakpointOptions {
  std::size_t max_points = 16;  ///< LinuxCNC lincurve: at most 16 (x, y) points
  /// Candidate breakpoints are measured samples; above this many samples a uniform subset is
  /// used as candidates (the error is still checked on every sample).
  std::size_t max_candidates = 600;
  bool is_valid(std::string* why) const;
};

/// At most opts.max_points breakpoints among the samples (always the first and the last) with
/// the smallest largest interpolation error over all samples; values equal the sample values.
/// Method: bisection on the error bound eps; for a given eps the fewest-breakpoint polyline is a
/// shortest path in the DAG of admissible segments, where a segment (i, j) is admissible when
/// every sample between lies within eps of the chord; all segments leaving i are tested in one
/// sweep by intersecting the cone of admissible slopes.  O(C * N) per bisection step.
CompensationTable make_breakpoint_table(const CompensationProfile& profile,
                                        const BreakpointOptions& opts = {});

/// Linear interpolation of (xs, ys) at x with the end values held outside.  xs increasing.
double interpolate_hold(const std::vector<double>& xs, const std::vector<double>& ys, double x);

}  // namespace errsep::core

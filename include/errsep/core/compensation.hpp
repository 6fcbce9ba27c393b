#pragma once
// Compensation tables from a measured straightness error (pure computation; the controller file
// formats are written by errsep/io/controller_tables.hpp).
//
// Sign convention (documented once, used by every table):
//   error      e(x) = actual - commanded position of the OUTPUT axis (the straightness direction)
//                     while the INPUT axis (the moving axis) is at x.  The four-sensor result S(x)
//                     is taken as this error: S > 0 means the carriage sits towards +direction.
//                     If your S has the opposite sense, set CompensationOptions::error_sign = -1.
//   compensation c(x) = -e(x), added by the controller to the output axis command, so that
//                     actual = commanded + c(x) + e(x) = commanded.
// The tables hold c in um here; writers convert to the controller's unit.
//
// A line is removed from e(x) first (end-point line by default): the slope of S relative to the
// other axis is set by how the reference artefact was aligned, not by the machine, and would
// otherwise be "compensated" as a squareness error that was never measured.
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "errsep/core/iso230.hpp"

namespace errsep::core {

struct CompensationOptions {
  /// Line removed from the error before tabulating (nullopt: keep S as it is).
  std::optional<ReferenceLine> remove_line = ReferenceLine::end_points;
  double error_sign = 1.0;  ///< +1: e = S; -1: e = -S (see the sign convention above)
  double step_mm = 10.0;    ///< spacing of a uniform table
  /// Largest number of points a uniform table may have (0: no limit).  Sinumerik: MD18342
  /// $MN_MM_CEC_MAX_POINTS[t] (828D: 200 per table); Beckhoff: kw.crosscomp.max_points.
  std::size_t max_points = 0;
  bool is_valid(std::string* why) const;
};

/// Table with uniformly spaced points: c(start_mm + i * step_mm) = comp_um[i].
struct UniformCompensationTable {
  double start_mm = 0;
  double step_mm = 1;
  std::vector<double> comp_um;
  double end_mm() const { return start_mm + step_mm * static_cast<double>(comp_um.size() - 1); }
  /// Largest |table interpolated linearly - (-error)| over the measured samples, um.
  double max_interpolation_error_um = 0;
};

/// The error e_i = error_sign * S_i minus the chosen line, at the measured positions.
std::vector<double> error_to_compensate(const std::vector<double>& x_mm,
                                        const std::vector<double>& s_um,
                                        const CompensationOptions& opts);

/// Uniform table over the measured range: nodes start at x_mm.front() with step_mm; the last node
/// is the first one at or beyond x_mm.back() (its value is the end value: controllers hold the
/// end value outside a table anyway).  Values are -e linearly interpolated at the nodes.  Throws
/// std::invalid_argument (bad options or profile, or more than max_points points).
UniformCompensationTable make_uniform_table(const std::vector<double>& x_mm,
                                            const std::vector<double>& s_um,
                                            const CompensationOptions& opts);

struct BreakpointOptions {
  std::size_t max_points = 16;  ///< LinuxCNC lincurve: at most 16 (x, y) points
  /// Candidate breakpoints are measured samples; above this many samples a uniform subset is
  /// used as candidates (the error is still checked on every sample).
  std::size_t max_candidates = 600;
  bool is_valid(std::string* why) const;
};

/// Piecewise-linear table with free breakpoints (LinuxCNC lincurve).
struct BreakpointTable {
  std::vector<double> x_mm;
  std::vector<double> comp_um;
  /// Largest |polyline - (-e)| over all samples.  Both are piecewise linear between samples and
  /// breakpoints are samples, so this is the largest error over the whole measured range.
  double max_interpolation_error_um = 0;
  double rms_interpolation_error_um = 0;
  std::size_t candidates = 0;  ///< number of candidate breakpoints considered
};

/// Chooses at most opts.max_points breakpoints among the samples (always the first and the last)
/// so that the largest interpolation error over all samples is smallest, with the breakpoint
/// values equal to the sample values.  Method: bisection on the error bound eps; for a given eps
/// the fewest-breakpoint polyline is a shortest path in the DAG of admissible segments, where a
/// segment (i, j) is admissible when every sample between lies within eps of the chord; all
/// segments leaving i are tested in one sweep by intersecting the cone of admissible slopes.
/// O(C * N) per bisection step (C candidates, N samples).
BreakpointTable make_breakpoint_table(const std::vector<double>& x_mm,
                                      const std::vector<double>& s_um,
                                      const CompensationOptions& opts,
                                      const BreakpointOptions& bopts = {});

/// Linear interpolation of (xs, ys) at x with the end values held outside (what lincurve and the
/// CEC/cross-compensation tables do).  xs strictly increasing.
double interpolate_hold(const std::vector<double>& xs, const std::vector<double>& ys, double x);

}  // namespace errsep::core

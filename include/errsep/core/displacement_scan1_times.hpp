#pragma once
// Recorded scan-1 times against the declared scan plan of a two-axis measurement (issue 16
// item 2).  The two-axis refine builds its drift and thermal columns from the declared plan's
// reading times (TwoAxisScanOrder, displacement_effects.hpp), not from the file's, so a file whose
// recorded scan-1 times (t_scan1_s) read the grid in another order would be refined against the
// wrong times, silently.  The check is of the order only (one O(nx·ny) pass per order tried): the
// stated sample period and pause are taken as given.  It returns a finding; the caller words it.
#include <Eigen/Core>
#include <optional>

#include "errsep/core/displacement_effects.hpp"

namespace errsep::core {

/// Reading orders of scan 1 on the grid.
enum class Scan1Order {
  raster_x_fastest,  ///< the paper's raster (TwoAxisScanOrder::diagonal_scan1 false)
  diagonal,          ///< wrapped diagonals (diagonal_scan1 true)
  raster_y_fastest,  ///< a raster y fastest, then x: no plan of the refine (named in findings)
};

/// Reading index (0 first) of grid point (i, j) in scan 1 read in this order: the order of
/// TwoAxisScanOrder::time_s, independent of the sample period.
int scan1_reading_index(Scan1Order order, int i, int j, int nx, int ny);

struct Scan1TimesFinding {
  bool consistent = true;  ///< nothing recorded, or the times increase along the declared order
  Scan1Order declared = Scan1Order::raster_x_fastest;
  /// The first pair out of order: (i0, j0) is read just before (i1, j1) in the declared order, but
  /// its recorded time t0_s is not earlier than t1_s.  -1 / 0 when consistent.
  int i0 = -1, j0 = -1, i1 = -1, j1 = -1;
  double t0_s = 0, t1_s = 0;
  /// The order the times do follow: the refine's other plan, else a raster y fastest; empty when
  /// neither (or when consistent).
  std::optional<Scan1Order> recorded;
};

/// Checks t_scan1_s (nx × ny; empty: nothing recorded) against the declared plan's scan 1.
Scan1TimesFinding check_scan1_times(const Eigen::MatrixXd& t_scan1_s,
                                    const TwoAxisScanOrder& declared);

}  // namespace errsep::core

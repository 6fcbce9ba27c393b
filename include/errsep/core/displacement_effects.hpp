#pragma once
// Effects the displacement method's joint model (displacement_joint.hpp) lacks, as additions to
// the sensors' readings of the two-axis stage (Haramiishi et al. 2024, Eqs. 10-19).  One model,
// used twice: the simulator injects them (undeclared) and the refine (displacement_refine.hpp)
// builds its extra least-squares columns from them with one unit parameter at a time, so the two
// cannot disagree on a sign or a time origin.
//
//   linear drift     sensor k reads + v_k·t (µm/s), t since the first reading of scan 1
//   thermal drift    sensor k reads + a_k·(1 − exp(−t/τ)), one τ for all sensors (they warm up
//                    together, as effect_thermal_drift.hpp of the four-sensor loop)
//   table tilt       between the scans the x table tilts about the y axis by β_x (µrad) and the
//                    y table about the x axis by β_y: in scan 2 the sensors fixed to the base that
//                    read the x table and what it carries (1, 2 and 0) read + β_x·(x − x_mid), the
//                    sensors riding on the x table that read the y table (3, 4) and sensor 0 read
//                    + β_y·(y − y_mid) (µrad·mm = 10⁻³ µm).  The sign of a tilt's pivot constant is
//                    not modelled: a constant between the scans is what a zero shift of sensor 0
//                    does too (displacement_residuals.hpp), and the joint model absorbs it.
//
// Times: a raster of n_x·n_y readings per scan at sample_period_s each, scan 1 x fastest (the
// paper); scan 2 starts pause_between_scans_s after scan 1 ended and runs its raster x fastest
// (the paper) or y fastest (y_fastest_scan2), forwards or backwards (reverse_scan2).  In the
// paper's plan every grid point is read the same time after its scan-1 reading, so a linear drift
// is one constant in every scan difference (invisible); backwards, the offset varies along the
// raster's slow axis (y) by ~2·n_x·n_y samples but along its fast axis (x, what the reference Y
// sensors 3-4 compare) only by ~2·n_x; y fastest, it varies by ~n_x·n_y along both axes, so the
// drift of every sensor shows in its redundancy (see displacement_refine.hpp).
//
// A thermal drift that settles within about a scan is seen by the reference Y sensors 3-4 only
// through scan 1's time variation along a column, which a raster x fastest compresses into n_x
// samples.  diagonal_scan1 reads scan 1 along wrapped diagonals: reading k = q·n_x + i is at
// (i, (q + i) mod n_y), so x still steps by one every reading, but every row and every column is
// read over the whole of scan 1 (row i at k ≡ i mod n_x, column j at q = (j − i) mod n_y; with
// n_x < n_y a column spans ~n_x² samples, still n_x times a raster's).
#include <Eigen/Core>
#include <array>
#include <string>

#include "errsep/core/two_axis_displacement.hpp"

namespace errsep::core {

/// When each reading of a two-axis measurement is taken.
struct TwoAxisScanOrder {
  double sample_period_s = 1.0;
  double pause_between_scans_s = 0.0;
  bool reverse_scan2 = false;    ///< scan 2 runs the raster from its last point back to its first
  bool y_fastest_scan2 = false;  ///< scan 2's raster runs y fastest (scan 1's: x fastest)
  /// Scan 1 along wrapped diagonals instead of the paper's raster (file comment).
  bool diagonal_scan1 = false;
  /// Time (s) of the reading at grid point (i, j) in scan 1 or 2, t = 0 at the first reading.
  double time_s(int scan, int i, int j, int nx, int ny) const;
  bool is_valid(std::string* why = nullptr) const;
  /// "scan 2 as scan 1 (paper)", "scan 2 backwards", "scan 2 y fastest, backwards", …
  std::string plan_name() const;
};

/// Sizes of the effects (0 = absent).  Sensors are indexed 0..4 as in the paper.
struct DisplacementDisturbance {
  std::array<double, 5> drift_um_per_s{};  ///< linear drift of each sensor
  std::array<double, 5> thermal_um{};      ///< first-order thermal amplitude of each sensor
  double thermal_tau_s = 600.0;            ///< its time constant
  double tilt_x_urad = 0.0;                ///< x table about y between the scans
  double tilt_y_urad = 0.0;                ///< y table about x between the scans
  bool is_valid(std::string* why = nullptr) const;
  /// What sensor `sensor` reads in addition at time t_s in scan `scan`, at x − x_mid and
  /// y − y_mid (mm).
  double reading_um(int sensor, int scan, double t_s, double x_rel_mm, double y_rel_mm) const;
};

/// Adds the disturbance to every reading of the scan (s0_2_um only when present).  Throws
/// std::invalid_argument for invalid arguments or reading matrices of unequal size.
void add_disturbance(TwoAxisScan& scan, const DisplacementDisturbance& d,
                     const TwoAxisScanOrder& order);

}  // namespace errsep::core

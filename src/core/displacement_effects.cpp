#include "errsep/core/displacement_effects.hpp"

#include <cmath>
#include <stdexcept>

namespace errsep::core {
namespace {

/// µrad · mm -> µm
constexpr double kUmPerUradMm = 1e-3;

}  // namespace

double TwoAxisScanOrder::time_s(int scan, int i, int j, int nx, int ny) const {
  if (scan == 1) {
    if (!diagonal_scan1) return (j * nx + i) * sample_period_s;  // raster index, x fastest
    const int q = ((j - i) % ny + ny) % ny;  // the diagonal through (i, j) (file comment)
    return (q * nx + i) * sample_period_s;
  }
  const int k = y_fastest_scan2 ? i * ny + j : j * nx + i;
  const int n = nx * ny;
  const double t0 = n * sample_period_s + pause_between_scans_s;
  return t0 + (reverse_scan2 ? n - 1 - k : k) * sample_period_s;
}

std::string TwoAxisScanOrder::plan_name() const {
  const std::string s1 = diagonal_scan1 ? "scan 1 diagonal, " : "";
  if (!reverse_scan2 && !y_fastest_scan2)
    return diagonal_scan1 ? s1 + "scan 2 raster x fastest" : "scan 2 as scan 1 (paper)";
  std::string s;
  if (y_fastest_scan2) s += ", y fastest";
  if (reverse_scan2) s += ", backwards";
  return s1 + "scan 2" + s.substr(1);
}

bool TwoAxisScanOrder::is_valid(std::string* why) const {
  if (!(std::isfinite(sample_period_s) && sample_period_s >= 0 &&
        std::isfinite(pause_between_scans_s) && pause_between_scans_s >= 0)) {
    if (why) *why = "scan order: sample_period_s must be >= 0 and pause_between_scans_s >= 0";
    return false;
  }
  return true;
}

bool DisplacementDisturbance::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = "disturbance: " + m;
    return false;
  };
  for (int k = 0; k < 5; ++k)
    if (!std::isfinite(drift_um_per_s[k]) || !std::isfinite(thermal_um[k]))
      return fail("drift_um_per_s and thermal_um of sensor " + std::to_string(k) +
                  " must be finite");
  if (!(std::isfinite(thermal_tau_s) && thermal_tau_s > 0))
    return fail("thermal_tau_s = " + std::to_string(thermal_tau_s) + ": must be > 0");
  if (!std::isfinite(tilt_x_urad) || !std::isfinite(tilt_y_urad))
    return fail("tilt_x_urad and tilt_y_urad must be finite");
  return true;
}

double DisplacementDisturbance::reading_um(int sensor, int scan, double t_s, double x_rel_mm,
                                           double y_rel_mm) const {
  double v = drift_um_per_s[sensor] * t_s;
  if (thermal_um[sensor] != 0) v += thermal_um[sensor] * (1.0 - std::exp(-t_s / thermal_tau_s));
  if (scan == 2) {
    if (sensor == 0 || sensor == 1 || sensor == 2) v += kUmPerUradMm * tilt_x_urad * x_rel_mm;
    if (sensor == 0 || sensor == 3 || sensor == 4) v += kUmPerUradMm * tilt_y_urad * y_rel_mm;
  }
  return v;
}

void add_disturbance(TwoAxisScan& s, const DisplacementDisturbance& d,
                     const TwoAxisScanOrder& order) {
  std::string why;
  if (!d.is_valid(&why) || !order.is_valid(&why)) throw std::invalid_argument(why);
  const auto nx = static_cast<int>(s.x_mm.size()), ny = static_cast<int>(s.y_mm.size());
  Eigen::MatrixXd* m[2][5] = {{&s.s0_1_um, &s.s1_1_um, &s.s2_1_um, &s.s3_1_um, &s.s4_1_um},
                              {&s.s0_2_um, &s.s1_2_um, &s.s2_2_um, &s.s3_2_um, &s.s4_2_um}};
  for (int scan = 1; scan <= 2; ++scan)
    for (int k = 0; k < 5; ++k) {
      auto& r = *m[scan - 1][k];
      if (scan == 2 && k == 0 && r.size() == 0) continue;  // sensor 0 read once
      if (r.rows() != nx || r.cols() != ny)
        throw std::invalid_argument("add_disturbance: reading matrix of sensor " +
                                    std::to_string(k) + ", scan " + std::to_string(scan) +
                                    " is not nx x ny");
    }
  if (nx == 0 || ny == 0) return;
  const double xm = 0.5 * (s.x_mm(0) + s.x_mm(nx - 1)), ym = 0.5 * (s.y_mm(0) + s.y_mm(ny - 1));
  for (int scan = 1; scan <= 2; ++scan)
    for (int k = 0; k < 5; ++k) {
      auto& r = *m[scan - 1][k];
      if (r.size() == 0) continue;
      for (int j = 0; j < ny; ++j)
        for (int i = 0; i < nx; ++i)
          r(i, j) += d.reading_um(k, scan, order.time_s(scan, i, j, nx, ny), s.x_mm(i) - xm,
                                  s.y_mm(j) - ym);
    }
}

}  // namespace errsep::core

#include "errsep/core/displacement_simulation.hpp"

#include <cmath>
#include <stdexcept>

#include "errsep/core/noise.hpp"

namespace errsep::core {
namespace {

constexpr double kPi = 3.141592653589793;
/// rad · mm -> µm
constexpr double kUmPerRadMm = 1000.0;

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("displacement simulation: " + what);
}

bool finite_nonneg(double v) {
  return std::isfinite(v) && v >= 0;
}

}  // namespace

bool SensorErrorModel::is_valid(std::string* why) const {
  if (!finite_nonneg(noise_sigma_um)) {
    if (why) *why = "noise_sigma_um = " + std::to_string(noise_sigma_um) + ": must be >= 0";
    return false;
  }
  if (!std::isfinite(drift_um_per_s)) {
    if (why) *why = "drift_um_per_s must be finite";
    return false;
  }
  return true;
}

bool OneAxisSimOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(std::isfinite(sample_interval_mm) && sample_interval_mm > 0))
    return fail("sample_interval_mm must be finite and > 0");
  if (!(std::isfinite(length_mm) && length_mm >= sample_interval_mm))
    return fail("length_mm = " + std::to_string(length_mm) + ": must be >= sample_interval_mm");
  if (!(std::isfinite(displacement_mm) && displacement_mm > 0))
    return fail("displacement_mm must be finite and > 0");
  if (!std::isfinite(displacement_bias_mm) || !finite_nonneg(displacement_sigma_mm))
    return fail("displacement_bias_mm must be finite and displacement_sigma_mm >= 0");
  std::string sub;
  if (!workpiece_sensor.is_valid(&sub)) return fail("workpiece_sensor." + sub);
  if (!reference_sensor.is_valid(&sub)) return fail("reference_sensor." + sub);
  if (!finite_nonneg(timing.sample_period_s) || !finite_nonneg(timing.pause_between_scans_s))
    return fail("timing: sample_period_s and pause_between_scans_s must be >= 0");
  if (!std::isfinite(workpiece_thermal_um) || !std::isfinite(reference_thermal_um) ||
      !(std::isfinite(thermal_tau_s) && thermal_tau_s > 0))
    return fail("workpiece_thermal_um, reference_thermal_um must be finite, thermal_tau_s > 0");
  return true;
}

OneAxisSimData simulate_one_axis(const OneAxisTruth& truth, const OneAxisSimOptions& opts) {
  std::string why;
  require(opts.is_valid(&why), why);
  require(truth.w_um && truth.r_um && truth.m_um, "truth functions w, r, m must all be set");
  const auto n =
      static_cast<Eigen::Index>(std::floor(opts.length_mm / opts.sample_interval_mm + 1e-9)) + 1;
  NoiseSource rng(opts.seed);
  OneAxisSimData d;
  d.x_mm.resize(n);
  d.w_um.resize(n);
  d.r_um.resize(n);
  d.m_um.resize(n);
  d.s1_1_um.resize(n);
  d.s2_1_um.resize(n);
  d.s2_2_um.resize(n);
  const double T = opts.timing.sample_period_s;
  auto t2 = [&](Eigen::Index k) {
    return (n + (opts.reverse_scan2 ? n - 1 - k : k)) * T + opts.timing.pause_between_scans_s;
  };
  for (Eigen::Index k = 0; k < n; ++k) {
    const double x = k * opts.sample_interval_mm;
    d.x_mm(k) = x;
    d.w_um(k) = truth.w_um(x);
    d.r_um(k) = truth.r_um(x);
    d.m_um(k) = truth.m_um(x);
    const double t = k * T;
    // Eqs. (1), (2): scan 1.
    d.s1_1_um(k) = d.w_um(k) + d.m_um(k) + opts.workpiece_sensor.drift_um_per_s * t +
                   rng.normal(opts.workpiece_sensor.noise_sigma_um);
    d.s2_1_um(k) = d.r_um(k) + d.m_um(k) + opts.reference_sensor.drift_um_per_s * t +
                   rng.normal(opts.reference_sensor.noise_sigma_um);
  }
  d.applied_displacement_mm =
      opts.displacement_mm + opts.displacement_bias_mm + rng.normal(opts.displacement_sigma_mm);
  for (Eigen::Index k = 0; k < n; ++k) {
    // Eq. (3): scan 2, reference traversed; the motion error repeats.
    const double t = t2(k);
    d.s2_2_um(k) = truth.r_um(d.x_mm(k) + d.applied_displacement_mm) + d.m_um(k) +
                   opts.reference_sensor.drift_um_per_s * t +
                   rng.normal(opts.reference_sensor.noise_sigma_um);
  }
  d.s1_2_um.resize(n);
  for (Eigen::Index k = 0; k < n; ++k) {
    // Eq. (1) in scan 2, read with the reference sensor's scan-2 reading.
    const double t = t2(k);
    d.s1_2_um(k) = d.w_um(k) + d.m_um(k) + opts.workpiece_sensor.drift_um_per_s * t +
                   rng.normal(opts.workpiece_sensor.noise_sigma_um);
  }
  d.t1_s.resize(n);
  d.t2_s.resize(n);
  for (Eigen::Index k = 0; k < n; ++k) {
    d.t1_s(k) = k * T;
    d.t2_s(k) = t2(k);
  }
  auto thermal = [&](double a, double t) {
    return a == 0 ? 0.0 : a * (1.0 - std::exp(-t / opts.thermal_tau_s));
  };
  for (Eigen::Index k = 0; k < n; ++k) {
    d.s1_1_um(k) += thermal(opts.workpiece_thermal_um, d.t1_s(k));
    d.s1_2_um(k) += thermal(opts.workpiece_thermal_um, d.t2_s(k));
    d.s2_1_um(k) += thermal(opts.reference_thermal_um, d.t1_s(k));
    d.s2_2_um(k) += thermal(opts.reference_thermal_um, d.t2_s(k));
  }
  return d;
}

OneAxisTruth haramiishi2024_fig5_truth() {
  OneAxisTruth t;
  // Edges at 2.5 mm past the 5 mm grid so no sample sits on a discontinuity.
  t.w_um = [](double x) { return std::fmod(x + 2.5, 40.0) < 20.0 ? 500.0 : 0.0; };
  t.m_um = [](double x) { return 20.0 * std::sin(2.0 * kPi * x / 120.0); };
  t.r_um = [](double x) { return 0.05 * x; };
  return t;
}

bool TwoAxisSimOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (nx < 2 || ny < 2) return fail("nx, ny must be >= 2");
  if (!(dx_mm > 0 && dy_mm > 0 && std::isfinite(dx_mm) && std::isfinite(dy_mm)))
    return fail("dx_mm, dy_mm must be finite and > 0");
  if (!(displacement_x_mm > 0 && displacement_y_mm > 0))
    return fail("displacement_x_mm, displacement_y_mm must be > 0");
  if (!std::isfinite(displacement_bias_mm) || !finite_nonneg(displacement_sigma_mm))
    return fail("displacement_bias_mm must be finite and displacement_sigma_mm >= 0");
  std::string sub;
  if (!contact_sensor.is_valid(&sub)) return fail("contact_sensor." + sub);
  if (!eddy_sensor.is_valid(&sub)) return fail("eddy_sensor." + sub);
  if (!disturbance.is_valid(&sub)) return fail(sub);
  return true;
}

TwoAxisSimData simulate_two_axis(const TwoAxisTruth& tr, const TwoAxisSimOptions& opts) {
  std::string why;
  require(opts.is_valid(&why), why);
  require(tr.w_um && tr.r1x_um && tr.r2x_um && tr.r3y_um && tr.r4y_um && tr.ez_x_um &&
              tr.roll_x_rad && tr.ez_y_um && tr.pitch_y_rad,
          "every truth function must be set");
  const int nx = opts.nx, ny = opts.ny;
  const auto& g = opts.geometry;
  NoiseSource rng(opts.seed);
  TwoAxisSimData d;
  TwoAxisScan& s = d.scan;
  s.x_mm = Eigen::VectorXd::LinSpaced(nx, 0.0, (nx - 1) * opts.dx_mm);
  s.y_mm = Eigen::VectorXd::LinSpaced(ny, 0.0, (ny - 1) * opts.dy_mm);
  for (auto* m : {&s.s0_1_um, &s.s1_1_um, &s.s1_2_um, &s.s2_1_um, &s.s2_2_um, &s.s3_1_um,
                  &s.s3_2_um, &s.s4_1_um, &s.s4_2_um, &d.w_um, &d.m_w_um})
    m->resize(nx, ny);
  // Motion errors at the sensors (repeat in both scans).
  Eigen::MatrixXd m1(nx, ny), m2(nx, ny), m3(nx, ny), m4(nx, ny);
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const double x = s.x_mm(i), y = s.y_mm(j);
      const double ezx = tr.ez_x_um(x, y), roll = tr.roll_x_rad(x, y);
      const double ezy = tr.ez_y_um(x, y), pitch = tr.pitch_y_rad(x, y);
      const double l_yw = g.l_yw_mm + g.l_yw_per_x * (x - s.x_mm(0));
      m2(i, j) = ezx;                                   // sensor 2 at s = 0
      m1(i, j) = ezx + kUmPerRadMm * roll * g.l_xs_mm;  // sensor 1 at s = l_xs
      m4(i, j) = ezy;
      m3(i, j) = ezy + kUmPerRadMm * pitch * g.l_ys_mm;
      d.m_w_um(i, j) = ezx + kUmPerRadMm * roll * g.l_xw_mm + ezy + kUmPerRadMm * pitch * l_yw;
      d.w_um(i, j) = tr.w_um(x, y);
    }
  const double T = opts.timing.sample_period_s;
  const double se = opts.eddy_sensor.noise_sigma_um, sc = opts.contact_sensor.noise_sigma_um;
  const double de = opts.eddy_sensor.drift_um_per_s, dc = opts.contact_sensor.drift_um_per_s;
  // Scan 1 (Eqs. 10-14), raster x fastest (or along diagonals: TwoAxisScanOrder).
  const TwoAxisScanOrder order{T, opts.timing.pause_between_scans_s, opts.reverse_scan2,
                               opts.y_fastest_scan2, opts.diagonal_scan1};
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const double x = s.x_mm(i), y = s.y_mm(j), t = order.time_s(1, i, j, nx, ny);
      s.s0_1_um(i, j) = d.w_um(i, j) + d.m_w_um(i, j) + dc * t + rng.normal(sc);
      s.s1_1_um(i, j) = tr.r1x_um(x) + m1(i, j) + de * t + rng.normal(se);
      s.s2_1_um(i, j) = tr.r2x_um(x) + m2(i, j) + de * t + rng.normal(se);
      s.s3_1_um(i, j) = tr.r3y_um(y) + m3(i, j) + de * t + rng.normal(se);
      s.s4_1_um(i, j) = tr.r4y_um(y) + m4(i, j) + de * t + rng.normal(se);
    }
  const double ax =
      opts.displacement_x_mm + opts.displacement_bias_mm + rng.normal(opts.displacement_sigma_mm);
  const double ay =
      opts.displacement_y_mm + opts.displacement_bias_mm + rng.normal(opts.displacement_sigma_mm);
  // Scan 2 (Eqs. 16-19).
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const double x = s.x_mm(i), y = s.y_mm(j), t = order.time_s(2, i, j, nx, ny);
      s.s1_2_um(i, j) = tr.r1x_um(x + ax) + m1(i, j) + de * t + rng.normal(se);
      s.s2_2_um(i, j) = tr.r2x_um(x + ax) + m2(i, j) + de * t + rng.normal(se);
      s.s3_2_um(i, j) = tr.r3y_um(y + ay) + m3(i, j) + de * t + rng.normal(se);
      s.s4_2_um(i, j) = tr.r4y_um(y + ay) + m4(i, j) + de * t + rng.normal(se);
    }
  if (opts.record_s0_scan2) {
    s.s0_2_um.resize(nx, ny);
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const double t = order.time_s(2, i, j, nx, ny);
        s.s0_2_um(i, j) = d.w_um(i, j) + d.m_w_um(i, j) + dc * t + rng.normal(sc);
      }
  }
  add_disturbance(s, opts.disturbance, order);
  return d;
}

TwoAxisTruth example_two_axis_truth() {
  TwoAxisTruth t;
  t.w_um = [](double x, double y) {
    const double u = (x - 60.0) / 60.0, v = (y - 60.0) / 60.0;
    return 8.0 * (u * u + v * v) +
           2.0 * std::sin(2.0 * kPi * x / 40.0) * std::cos(2.0 * kPi * y / 60.0);
  };
  t.r1x_um = [](double x) { return 0.02 * x + 1.5 * std::sin(2.0 * kPi * x / 200.0); };
  t.r2x_um = [](double x) { return -0.01 * x + 1.0 * std::cos(2.0 * kPi * x / 150.0); };
  t.r3y_um = [](double y) { return 0.03 * y - 1.2 * std::sin(2.0 * kPi * y / 180.0); };
  t.r4y_um = [](double y) { return 0.5 * std::sin(2.0 * kPi * y / 90.0); };
  // Table sinks along travel (as Figs. 18-19) with a ripple from the screw.
  t.ez_x_um = [](double x, double) { return -0.1 * x + 3.0 * std::sin(2.0 * kPi * x / 50.0); };
  t.ez_y_um = [](double x, double y) {
    return -0.2 * y + 2.0 * std::cos(2.0 * kPi * y / 70.0) + 0.01 * x;
  };
  // Roll of the x table grows as the y table's load moves out (Fig. 20: along y); pitch of the
  // y table varies along x and y (Fig. 21).  Tens of µrad: 165 mm lever -> several µm.
  t.roll_x_rad = [](double x, double y) {
    return 1e-6 * (0.4 * y - 10.0 + 5.0 * std::sin(2.0 * kPi * x / 120.0));
  };
  t.pitch_y_rad = [](double x, double y) {
    return 1e-6 * (-0.3 * x + 15.0 * std::sin(2.0 * kPi * y / 100.0));
  };
  return t;
}

Eigen::MatrixXd simulate_three_sensor(const SlidewayProfiles& truth,
                                      const ThreeSensorSimOptions& opts) {
  std::string why;
  require(opts.sensor.is_valid(&why), "sensor." + why);
  require(opts.positions >= 1 && opts.s1 >= 1 && opts.s2 >= 1 && opts.sample_interval_mm > 0,
          "positions, s1, s2 must be >= 1 and sample_interval_mm > 0");
  require(truth.f_um && truth.S_um && truth.gamma_rad, "truth functions f, S, gamma must be set");
  NoiseSource rng(opts.seed);
  const double offsets_mm[3] = {0.0, opts.s1 * opts.sample_interval_mm,
                                (opts.s1 + opts.s2) * opts.sample_interval_mm};
  Eigen::MatrixXd m(opts.positions, 3);
  for (int n = 0; n < opts.positions; ++n) {
    const double x = n * opts.sample_interval_mm, t = n * 1.0;
    for (int j = 0; j < 3; ++j)
      m(n, j) = truth.f_um(x + offsets_mm[j]) + truth.S_um(x) +
                kUmPerRadMm * offsets_mm[j] * truth.gamma_rad(x) + opts.sensor.drift_um_per_s * t +
                rng.normal(opts.sensor.noise_sigma_um);
  }
  return m;
}

}  // namespace errsep::core

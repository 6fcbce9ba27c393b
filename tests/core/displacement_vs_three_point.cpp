// The generalised three-point method (Zhao et al. 2019's baseline) and a comparison with the
// one-axis displacement method (Haramiishi et al. 2024) on the same simulated slideway.  The
// four-sensor method is to join this comparison once it exists.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>

#include "errsep/core/displacement_method.hpp"
#include "errsep/core/displacement_simulation.hpp"
#include "errsep/core/four_sensor.hpp"
#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/core/three_point_method.hpp"

using namespace errsep::core;

namespace {

constexpr double kPi = 3.141592653589793;

SlidewayProfiles slideway() {
  SlidewayProfiles s;
  s.f_um = [](double x) {
    return 2.0 * std::sin(2 * kPi * x / 60.0) + 0.5 * std::cos(2 * kPi * x / 17.0);
  };
  s.S_um = [](double x) { return 20.0 * std::sin(2 * kPi * x / 120.0) - 0.05 * x; };
  s.gamma_rad = [](double x) { return 1e-6 * (5.0 * std::cos(2 * kPi * x / 80.0) + 0.02 * x); };
  return s;
}

/// v minus the straight line through its first and last value (the datum of Zhao Eq. 11).
Eigen::VectorXd endpoint_datum(const Eigen::VectorXd& v) {
  const Eigen::Index n = v.size();
  Eigen::VectorXd out(n);
  for (Eigen::Index k = 0; k < n; ++k)
    out(k) = v(k) - (v(0) + (v(n - 1) - v(0)) * double(k) / double(n - 1));
  return out;
}

Eigen::VectorXd sample(const AxisFn& f, Eigen::Index n, double dx) {
  Eigen::VectorXd v(n);
  for (Eigen::Index k = 0; k < n; ++k)
    v(k) = f(k * dx);
  return v;
}

}  // namespace

TEST_CASE("three-point method recovers f, S and gamma exactly from noise-free readings") {
  const auto truth = slideway();
  ThreeSensorSimOptions so;  // 23 positions, spacings 1, 1 -> f on 25 samples (0..120 mm)
  const Eigen::MatrixXd m = simulate_three_sensor(truth, so);
  ThreePointOptions o;
  const auto res = separate_three_point(m, o);
  REQUIRE(res.f_um.size() == 25);
  CHECK(res.null_modes == 0);
  const Eigen::VectorXd f_true = endpoint_datum(sample(truth.f_um, 25, 5.0));
  CHECK((res.f_um - f_true).cwiseAbs().maxCoeff() < 1e-9);
  // S and gamma come back relative to the datum line of f: S + line, gamma + line slope.
  const double f0 = truth.f_um(0), slope = (truth.f_um(120) - f0) / 120.0;  // µm/mm
  for (int n = 0; n < 23; ++n) {
    CHECK(res.S_um(n) == Approx(truth.S_um(5.0 * n) + f0 + slope * 5.0 * n).margin(1e-9));
    CHECK(res.gamma_rad(n) == Approx(truth.gamma_rad(5.0 * n) + slope / 1000.0).margin(1e-12));
  }
}

TEST_CASE("three-point method with two spacings: homogeneous modes counted, equations satisfied") {
  const auto truth = slideway();
  ThreeSensorSimOptions so;
  so.s1 = 1;
  so.s2 = 2;
  so.positions = 22;
  ThreePointOptions o;
  o.s1 = 1;
  o.s2 = 2;
  const auto res = separate_three_point(simulate_three_sensor(truth, so), o);
  CHECK(res.f_um.size() == 25);
  CHECK(res.null_modes == 1);  // q - (p+q) z^p + p z^(p+q) = (z-1)^2 (z+2)
  CHECK(res.residual_rms_um < 1e-9);
  std::string why;
  o.s2 = 0;
  CHECK_FALSE(o.is_valid(&why));
  CHECK_THAT(why, Catch::Contains("s2 = 0"));
  REQUIRE_THROWS_WITH(separate_three_point(Eigen::MatrixXd::Zero(5, 2), ThreePointOptions{}),
                      Catch::Contains("need 3"));
}

TEST_CASE("displacement vs three-point method on the same slideway (noise 0.1 um)") {
  // Same surface f, straightness S, tilt γ and sensor noise σ = 0.1 µm on every reading,
  // 120 mm at 5 mm.  Displacement method: workpiece sensor reads f, reference sensor reads a
  // reference piece r, both beside each other at the same x (tilt does not enter).  Three-point
  // method: sensors at 0, 5, 10 mm on the carriage.  Both errors judged against the endpoint datum.
  const auto truth = slideway();
  constexpr double kSigma = 0.1;
  constexpr int kRuns = 300;
  const Eigen::VectorXd f_true = endpoint_datum(sample(truth.f_um, 25, 5.0));
  Eigen::VectorXd ms_disp = Eigen::VectorXd::Zero(25), ms_three = Eigen::VectorXd::Zero(25);
  for (int run = 0; run < kRuns; ++run) {
    OneAxisTruth ot{truth.f_um, [](double x) { return 0.03 * x + std::sin(x / 30.0); }, truth.S_um};
    OneAxisSimOptions od;
    od.workpiece_sensor.noise_sigma_um = kSigma;
    od.reference_sensor.noise_sigma_um = kSigma;
    od.seed = 100 + run;
    const auto sd = simulate_one_axis(ot, od);
    DisplacementOptions dopt;
    const auto rd = separate_displacement(sd.s1_1_um, sd.s2_1_um, sd.s2_2_um, dopt);
    const Eigen::VectorXd ed = endpoint_datum(rd.w_um) - f_true;

    ThreeSensorSimOptions ts;
    ts.sensor.noise_sigma_um = kSigma;
    ts.seed = 100 + run;
    const auto rt = separate_three_point(simulate_three_sensor(truth, ts), ThreePointOptions{});
    const Eigen::VectorXd et = rt.f_um - f_true;
    ms_disp += ed.cwiseProduct(ed);
    ms_three += et.cwiseProduct(et);
  }
  ms_disp /= kRuns;
  ms_three /= kRuns;
  std::printf("\nslideway 120 mm at 5 mm, sigma %.2f um, %d runs: rms profile error [um]\n", kSigma,
              kRuns);
  std::printf("%8s %14s %12s\n", "x_mm", "displacement", "three-point");
  for (int k = 0; k < 25; k += 4)
    std::printf("%8.0f %14.3f %12.3f\n", 5.0 * k, std::sqrt(ms_disp(k)), std::sqrt(ms_three(k)));
  const double rms_d = std::sqrt(ms_disp.mean()), rms_t = std::sqrt(ms_three.mean());
  std::printf("%8s %14.3f %12.3f\n", "all", rms_d, rms_t);
  // Sequential first differences (one summation) against second differences (two summations):
  // the displacement method's error is expected to be the smaller one.
  CHECK(rms_d < rms_t);
  CHECK(rms_d > 0.0);
}

TEST_CASE("displacement, three-point and four-sensor methods on the same slideway") {
  // The four-sensor method (Zhao 2019, the lead's core/four_sensor.hpp) on the same f, S, γ and
  // σ = 0.1 µm: configuration D2 = D3 = 5 mm, D4 = 25 mm, N = 25 reference samples (0..120 mm),
  // so P = 18 slide positions.  Checked: noise-free least squares recovers f (so the three are
  // compared on the same surface); printed: rms error of each method against the endpoint datum.
  const auto truth = slideway();
  SlidewayTruth fs_truth;
  fs_truth.f_um = truth.f_um;
  fs_truth.S_um = truth.S_um;
  fs_truth.gamma_rad = truth.gamma_rad;
  FourSensorConfig cfg;
  cfg.dx_mm = 5.0;
  cfg.s2 = 1;
  cfg.s3 = 1;
  cfg.s4 = 5;
  cfg.N = 25;
  const Eigen::VectorXd f_true = endpoint_datum(sample(truth.f_um, 25, 5.0));
  // This f has a bow of its own and the simulated zero-adjustment values are 0, so the gauge that
  // holds here is the sensor stage's (no quadratic part in e), not the default one (no bow in f).
  const CurvatureGauge gauge = CurvatureGauge::sensor_stage_without_curvature;
  {
    FourSensorOptions o = options_for_gauge(gauge);
    o.rule = LambdaRule::least_squares;
    o.compute_uncertainty = false;
    const auto r = separate_four_sensor(cfg, simulate_four_sensor(cfg, fs_truth, {}).m_um, o);
    REQUIRE(r.f_um.size() == 25);
    CHECK((r.f_um - f_true).cwiseAbs().maxCoeff() < 1e-6);
  }
  constexpr double kSigma = 0.1;
  constexpr int kRuns = 100;
  double ms[3] = {0, 0, 0};
  for (int run = 0; run < kRuns; ++run) {
    OneAxisTruth ot{truth.f_um, [](double x) { return 0.03 * x + std::sin(x / 30.0); }, truth.S_um};
    OneAxisSimOptions od;
    od.workpiece_sensor.noise_sigma_um = kSigma;
    od.reference_sensor.noise_sigma_um = kSigma;
    od.seed = 100 + run;
    const auto sd = simulate_one_axis(ot, od);
    const auto rd =
        separate_displacement(sd.s1_1_um, sd.s2_1_um, sd.s2_2_um, DisplacementOptions{});
    ms[0] += (endpoint_datum(rd.w_um) - f_true).squaredNorm() / 25;

    ThreeSensorSimOptions ts;
    ts.sensor.noise_sigma_um = kSigma;
    ts.seed = 100 + run;
    const auto rt = separate_three_point(simulate_three_sensor(truth, ts), ThreePointOptions{});
    ms[1] += (rt.f_um - f_true).squaredNorm() / 25;

    FourSensorSimOptions fo;
    fo.sigma_um = kSigma;
    fo.seed = 100 + run;
    FourSensorOptions o = options_for_gauge(gauge);  // the paper's system, L-curve λ
    o.compute_uncertainty = false;
    const auto r4 = separate_four_sensor(cfg, simulate_four_sensor(cfg, fs_truth, fo).m_um, o);
    ms[2] += (r4.f_um - f_true).squaredNorm() / 25;
  }
  std::printf(
      "\nsame slideway, sigma %.2f um, %d runs, rms profile error over 0..120 mm [um]:\n"
      "  displacement (two-point) %.3f, three-point %.3f, four-sensor (L-curve) %.3f\n",
      kSigma, kRuns, std::sqrt(ms[0] / kRuns), std::sqrt(ms[1] / kRuns), std::sqrt(ms[2] / kRuns));
  for (double m : ms)
    CHECK(std::isfinite(m));
}

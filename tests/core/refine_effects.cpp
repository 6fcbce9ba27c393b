// The refinement loop (core/refine.hpp) on simulated four-sensor scans (Zhao 2019 Example 1/2
// geometry, N = 69, Δx = 5 mm) with one effect of the library injected into the readings and not
// declared: the loop must pick that effect, recover its parameters within the stated standard
// uncertainty along every direction the data determine, and at least halve the error of S and f
// against the truth.
#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>

#include "errsep/core/effect_drift.hpp"
#include "errsep/core/effect_periodic.hpp"
#include "errsep/core/refine.hpp"
#include "support/refine_cases.hpp"

using namespace errsep::core;
using errsep::test::make_refine_case;
using errsep::test::RefineCase;

namespace {

void print_steps(const char* title, const RefineResult& r) {
  std::printf("%s\n  %s\n", title, r.brief_report().c_str());
  for (const auto& s : r.steps) {
    std::printf("  step %d %-8s rms %.4f -> %.4f um, whiteness p = %.3g", s.index, s.effect.c_str(),
                s.rms_before_um, s.rms_after_um, s.whiteness_after.p_value);
    if (s.error_before && s.error_after)
      std::printf(", error S %.4f -> %.4f um, gamma %.3f -> %.3f urad, f %.4f -> %.4f um",
                  s.error_before->S_um, s.error_after->S_um, s.error_before->gamma_urad,
                  s.error_after->gamma_urad, s.error_before->f_um, s.error_after->f_um);
    std::printf("\n");
    for (Eigen::Index j = 0; j < s.parameters.size(); ++j)
      std::printf("      %-12s = %.6g +- %.3g\n",
                  s.parameter_names[static_cast<std::size_t>(j)].c_str(), s.parameters(j),
                  s.u_parameters(j));
  }
}

// Along every determined direction w of the step: |wᵀ(p − p_true)| < 3·sqrt(wᵀCw).
void check_parameters(const RefineStep& s, const Eigen::VectorXd& p_true) {
  REQUIRE(s.parameters.size() == p_true.size());
  REQUIRE(s.identifiable >= 1);
  for (Eigen::Index j = 0; j < s.identifiable_directions.cols(); ++j) {
    const Eigen::VectorXd w = s.identifiable_directions.col(j);
    const double d = w.dot(s.parameters - p_true);
    const double u = std::sqrt(w.dot(s.covariance * w));
    INFO("direction " << j << ": w'(p - p_true) = " << d << ", u = " << u);
    CHECK(u > 0);
    CHECK(std::abs(d) < 3.0 * u);
  }
}

void check_identified(const RefineResult& r, const std::string& effect,
                      const Eigen::VectorXd& p_true, bool error_must_halve = true) {
  REQUIRE(r.steps.size() >= 2);
  const RefineStep& s = r.steps[1];
  CHECK(s.effect == effect);
  CHECK(s.p_value < 1e-6);
  check_parameters(s, p_true);
  REQUIRE(s.error_before);
  REQUIRE(s.error_after);
  if (error_must_halve) {
    CHECK(s.error_after->S_um < 0.5 * s.error_before->S_um);
    CHECK(s.error_after->f_um < 0.5 * s.error_before->f_um);
  }
  CHECK(s.rms_after_um < s.rms_before_um);
  // Nothing else of the library is added, and what is left is noise.
  CHECK(r.steps.size() == 2);
  CHECK(r.residual_white());
}

RefineResult run(const RefineCase& c, const RefineOptions& o = {}) {
  return refine_four_sensor(c.cfg, c.sim.m_um, Eigen::MatrixXd(), o, &c.truth);
}

}  // namespace

TEST_CASE("PE1: sensor spacings off by about a mm are found and corrected") {
  // PE1 is seen through the slope of f at each sensor: Example 2's reference surface (Eq. 24,
  // k = 3) gives it a signature well above the noise.
  const Eigen::Vector3d dD(0.8, -0.6, 0.6);  // mm: D = 5.8, 4.4, 25.6 instead of 5, 5, 25
  const auto c = make_refine_case(
      0.02, 11,
      [&](FourSensorSimOptions& so) {
        so.actual_spacing_mm = std::array<double, 3>{5.0 + dD(0), 5.0 + dD(1), 25.0 + dD(2)};
      },
      {}, 3);
  const auto r = run(c);
  print_steps("PE1 dD = (0.8, -0.6, 0.6) mm, Example 2 (k = 3), sigma 0.02 um", r);
  check_identified(r, "pe1", dD);
}

TEST_CASE("gain: a 5 % gain error of configuration 3 is found and corrected") {
  const Eigen::Vector3d g(0.0, 0.05, 0.0);
  const auto c = make_refine_case(0.02, 12, {}, [&](Eigen::MatrixXd& m, const Eigen::MatrixXd&) {
    for (int i = 1; i < 4; ++i)
      m.col(i) *= 1.0 + g(i - 1);
  });
  const auto r = run(c);
  print_steps("gain g = (0, 0.05, 0), sigma 0.02 um", r);
  check_identified(r, "gain", g);
}

TEST_CASE("drift: only one combination of the four drift rates is identifiable") {
  // m_i += a_i·t_i with t affine in x within each traverse (scan order t = i·T + x/v, or
  // backwards) adds a constant per configuration (absorbed by e) and x_n·b_i per position: S and
  // γ absorb the part of b affine in the offset, f's cubic term one more combination.
  const auto c0 = make_refine_case(0.02, 13);
  EffectContext ctx;
  ctx.cfg = c0.cfg;
  ctx.m_um = c0.sim.m_um;
  ctx.t_s = scan_order_times_s(c0.cfg);
  const DriftEffect drift;
  const Eigen::MatrixXd Jr = reduce_columns(c0.cfg, drift.jacobian(Eigen::Vector4d::Zero(), ctx));
  const Identifiability id = check_identifiability(ResidualSpace(c0.cfg), Jr);
  CHECK(id.identifiable == 1);
  CHECK(id.null_directions.cols() == 3);
  // A common drift (one sensor drifting in time) is among the null directions.
  Eigen::MatrixXd Z = Eigen::HouseholderQR<Eigen::MatrixXd>(id.null_directions).householderQ() *
                      Eigen::MatrixXd::Identity(4, 3);
  const Eigen::Vector4d common = Eigen::Vector4d::Constant(0.5);
  CHECK((Z * (Z.transpose() * common) - common).norm() < 1e-6);
  // Configurations 2 and 4 traversed backwards: still one.
  Eigen::MatrixXd t = ctx.t_s;
  const int P = c0.cfg.positions();
  for (int n = 0; n < P; ++n)
    for (int i : {1, 3})
      t(n, i) = ctx.t_s(P - 1 - n, i);
  ctx.t_s = t;
  const Eigen::MatrixXd Jb = reduce_columns(c0.cfg, drift.jacobian(Eigen::Vector4d::Zero(), ctx));
  CHECK(check_identifiability(ResidualSpace(c0.cfg), Jb).identifiable == 1);
}

TEST_CASE("drift: the identifiable drift combination is found and removed") {
  const auto c0 = make_refine_case(0.02, 13);
  EffectContext ctx;
  ctx.cfg = c0.cfg;
  ctx.m_um = c0.sim.m_um;
  ctx.t_s = scan_order_times_s(c0.cfg);
  const Eigen::MatrixXd Jr =
      reduce_columns(c0.cfg, DriftEffect().jacobian(Eigen::Vector4d::Zero(), ctx));
  const Identifiability id = check_identifiability(ResidualSpace(c0.cfg), Jr);
  REQUIRE(id.identifiable == 1);
  Eigen::MatrixXd Z = Eigen::HouseholderQR<Eigen::MatrixXd>(id.null_directions).householderQ() *
                      Eigen::MatrixXd::Identity(4, id.null_directions.cols());
  Eigen::Vector4d a(0.0, 0.0, 0.02, 0.0);  // µm/s on configuration 3 ...
  a -= Z * (Z.transpose() * a);            // ... less what no scan can see
  std::printf("drift rates injected: %g %g %g %g um/s\n", a(0), a(1), a(2), a(3));
  const auto c = make_refine_case(0.02, 13, {}, [&](Eigen::MatrixXd& m, const Eigen::MatrixXd& t) {
    for (int i = 0; i < 4; ++i)
      m.col(i) += a(i) * t.col(i);
  });
  const auto r = run(c);
  print_steps("drift (identifiable combination), sigma 0.02 um", r);
  // That combination is by construction invisible to S, γ and f (it is what they cannot absorb),
  // so it biases the readings' residual, not the profiles: the error cannot fall by half; it must
  // end at the level of the same scan without drift.
  check_identified(r, "drift", a, false);
  const auto clean = run(c0);
  REQUIRE(clean.steps.front().error_after);
  std::printf("  same seed without drift: error S %.4f um, f %.4f um\n",
              clean.steps.front().error_after->S_um, clean.steps.front().error_after->f_um);
  CHECK(r.steps[1].error_after->S_um < 1.5 * clean.steps.front().error_after->S_um);
  CHECK(r.steps[1].error_after->f_um < 1.5 * clean.steps.front().error_after->f_um);
}

TEST_CASE("PE2: a smooth slide positioning error is found and corrected") {
  // Visible only through how f changes between the configurations' sample points, so the test
  // uses Example 2's reference surface (Eq. 24, k = 3) and a positioning error of 1 mm.
  const double A = 1000.0;  // µm
  const Eigen::Vector3d p(A, 0.6 * A, 0.3 * A);
  const auto c = make_refine_case(
      0.02, 14,
      [&](FourSensorSimOptions& so) {
        so.positioning_error_um = [p](double x) {
          const double u = 2.0 * x / 305.0 - 1.0;  // travel L = 305 mm
          return p(0) * u + p(1) * (1.5 * u * u - 0.5) + p(2) * (2.5 * u * u * u - 1.5 * u);
        };
      },
      {}, 3);
  const auto r = run(c);
  print_steps("PE2 Legendre (1000, 600, 300) um, Example 2 (k = 3), sigma 0.02 um", r);
  check_identified(r, "pe2", p);
}

TEST_CASE("periodic: a lead-screw-like periodic positioning error, period from the search") {
  const double A = 600.0, period = 23.0, phase = 0.3;
  const auto c = make_refine_case(0.02, 15, [&](FourSensorSimOptions& so) {
    so.positioning_error_um = [=](double x) {
      return A * std::sin(2.0 * std::numbers::pi * x / period + phase);
    };
  });
  const auto r = run(c);
  print_steps("periodic 600 um, 23 mm, sigma 0.02 um", r);
  REQUIRE(r.steps.size() >= 2);
  // The estimated period is on the search grid (4x oversampled in frequency): within a quarter
  // of a frequency bin of the truth.
  REQUIRE(r.effects.size() >= 1);
  const std::string desc = r.steps[1].description;
  std::printf("  chosen: %s\n", desc.c_str());
  const double dfreq = 1.0 / (4.0 * 305.0);
  double est_period = 0;
  REQUIRE(std::sscanf(desc.c_str(), "periodic slide positioning error, period %lf", &est_period) ==
          1);
  CHECK(std::abs(1.0 / est_period - 1.0 / period) <= 0.5 * dfreq + 1e-12);
  // The period is refined with a and b: the truth in the model's parameters is (a, b, 23 mm − the
  // grid period).
  const auto& per = dynamic_cast<const PeriodicEffect&>(*r.effects.front());
  check_identified(
      r, "periodic",
      Eigen::Vector3d(A * std::sin(phase), A * std::cos(phase), period - per.period_mm()));
  std::printf("  period %.4f +- %.4f mm (truth %g)\n", per.period_mm(r.parameters.front()),
              r.u_parameters.front()(2), period);
}

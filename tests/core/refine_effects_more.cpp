// The effects added after the first library, each injected without being declared and well
// above the noise: the loop (or, for two axes, the yaw refinement) must pick the effect, recover
// its parameters within the stated standard uncertainty along every direction the data determine,
// and at least halve the error against the truth (printed before and after).
//  - first-order thermal drift (effect_thermal_drift.hpp) and an S or γ that does not repeat
//    between traverses (effect_traverse.hpp) on simulated four-sensor scans (Zhao 2019 Example 1
//    geometry, N = 69, Δx = 5 mm, σ = 0.02 µm).  First, what of each effect one scan can identify
//    at all, against the base model and the linear drift; the injected effects are the
//    identifiable part (as for the linear drift in refine_effects.cpp): the rest of a real effect
//    is absorbed by f, S, γ and e and no refinement can remove it.
//  - yaw of the x table in the two-axis displacement method (two_axis_yaw.hpp, Haramiishi 2024):
//    seen by a lateral sensor pair, not by the paper's sensors.
#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <functional>
#include <string>
#include <tuple>
#include <utility>

#include "errsep/core/effect_drift.hpp"
#include "errsep/core/effect_thermal_drift.hpp"
#include "errsep/core/effect_traverse.hpp"
#include "errsep/core/refine.hpp"
#include "errsep/core/two_axis_yaw.hpp"
#include "support/refine_cases.hpp"

using namespace errsep::core;
using errsep::test::make_refine_case;
using errsep::test::RefineCase;

namespace {

using errsep::test::add_traverse_polynomials;
using errsep::test::check_identified;
using errsep::test::null_basis;
using errsep::test::print_steps;
using errsep::test::scan_context;

RefineResult run(const RefineCase& c, const RefineOptions& o = {}) {
  return refine_four_sensor(c.cfg, c.sim.m_um, Eigen::MatrixXd(), o, &c.truth);
}

// w estimate minus truth without its mean (the initial values of Eq. 9 leave w up to a constant).
double w_error_rms(const Eigen::MatrixXd& w_est, const Eigen::MatrixXd& w_true) {
  Eigen::MatrixXd e = w_est - w_true;
  e.array() -= e.mean();
  return std::sqrt(e.squaredNorm() / static_cast<double>(e.size()));
}

// A workpiece with an inclined face (10 and 5 µm/mm) on the example stage: yaw acts on heights
// only through slopes, so a flat workpiece would not show it.
TwoAxisTruth inclined_truth() {
  TwoAxisTruth t = example_two_axis_truth();
  const GridFn w0 = t.w_um;
  t.w_um = [w0](double x, double y) { return w0(x, y) + 10.0 * x + 5.0 * y; };
  return t;
}

// Yaw ψ = Σ c_kl P_k(u) P_l(v) on the 120 mm x 120 mm grid, c in µrad (order (k, l) =
// (0,0), (0,1), (1,0), (1,1), (2,0), (2,1) as YawRefineOptions with degrees 2, 1).
YawTruth yaw_truth(const Eigen::VectorXd& c_urad) {
  YawTruth y;
  y.yaw_rad = [c_urad](double x, double yy) {
    const double u = x / 60.0 - 1.0, v = yy / 60.0 - 1.0;
    const double P[3] = {1.0, u, 1.5 * u * u - 0.5}, Q[2] = {1.0, v};
    double s = 0;
    int k = 0;
    for (int a = 0; a <= 2; ++a)
      for (int b = 0; b <= 1; ++b)
        s += c_urad(k++) * P[a] * Q[b];
    return 1e-6 * s;
  };
  y.side_um = [](double xi) {
    return 2.0 * std::sin(2.0 * 3.141592653589793 * xi / 150.0) + 0.01 * xi;
  };
  y.offset_a_um = 12.3;  // the lateral sensors' zero offsets
  y.offset_b_um = -40.0;
  y.lateral_um = [](double x, double yy) {
    return 3.0 * std::sin(2.0 * 3.141592653589793 * x / 80.0) + 0.02 * yy;
  };
  return y;
}

// Is v (parameter units) in the span of the orthonormal columns of Z?
double distance_to_span(const Eigen::MatrixXd& Z, const Eigen::VectorXd& v) {
  return (v - Z * (Z.transpose() * v)).norm() / v.norm();
}

}  // namespace

TEST_CASE(
    "thermal drift: one amplitude combination and tau identifiable, also after linear drift") {
  const auto c0 = make_refine_case(0.02, 31);
  const EffectContext ctx = scan_context(c0);
  const ResidualSpace base(c0.cfg);
  const Eigen::MatrixXd Jd =
      reduce_columns(c0.cfg, DriftEffect().jacobian(Eigen::Vector4d::Zero(), ctx));
  ResidualSpace with_drift(c0.cfg);
  REQUIRE(with_drift.add(Jd) == 1);
  const double v = 10.0;  // mm/s, the speed scan_order_times_s assumes
  const double T = c0.cfg.positions() * c0.cfg.dx_mm / v;
  const auto O = c0.cfg.offsets_mm();
  for (double tau : ThermalDriftEffect::tau_grid_s(ctx.t_s)) {
    const ThermalDriftEffect th(tau);
    Eigen::VectorXd p = Eigen::VectorXd::Zero(5);
    p(2) = 1.0;  // a ≠ 0, or τ's column is zero
    const Eigen::MatrixXd J = reduce_columns(c0.cfg, th.jacobian(p, ctx));
    const Identifiability id_a = check_identifiability(base, J.leftCols(4));
    const Identifiability id_all = check_identifiability(base, J);
    const Identifiability id_d = check_identifiability(with_drift, J.leftCols(4));
    std::printf(
        "tau %7.2f s: of a, %d identifiable (relative sv %.3g), %d with tau; after the "
        "linear drift %d (relative sv %.3g)\n",
        tau, id_a.identifiable, id_a.relative_sv(0), id_all.identifiable, id_d.identifiable,
        id_d.relative_sv(0));
    CHECK(id_a.identifiable == 1);
    CHECK(id_all.identifiable == 2);
    CHECK(id_d.identifiable == 1);
    ResidualSpace with_thermal(c0.cfg);
    with_thermal.add(J);
    const Identifiability d_after = check_identifiability(with_thermal, Jd);
    std::printf("   linear drift after the thermal drift: %d identifiable (relative sv %.3g)\n",
                d_after.identifiable, d_after.relative_sv(0));
    // The null directions are the ones the header names: b_i = −a_i·exp(−i·T/τ) common (S),
    // proportional to O_i (γ), proportional to exp(−O_i/(v·τ)) (an exponential f).
    const Eigen::MatrixXd Z = null_basis(id_a);
    REQUIRE(Z.cols() == 3);
    Eigen::Vector4d common, tilt, expf;
    for (int i = 0; i < 4; ++i) {
      const double back = std::exp(i * T / tau);  // a_i = −b_i·exp(i·T/τ)
      common(i) = back;
      tilt(i) = O[static_cast<std::size_t>(i)] * back;
      expf(i) = std::exp(-O[static_cast<std::size_t>(i)] / (v * tau)) * back;
    }
    CHECK(distance_to_span(Z, common) < 1e-6);
    CHECK(distance_to_span(Z, tilt) < 1e-6);
    CHECK(distance_to_span(Z, expf) < 1e-6);
  }
}

// Until stop 26 this asserted that S, gamma and f halve: the truth was built with no part in the
// null space and the determined part was applied.  The refine cannot know that part is zero: from
// one scan the rest of the effect is undetermined and could move S beyond u_S, so the effect is
// now reported "not identifiable from this plan" and carried in u_S, not applied (issue 16 item
// 1: applying the determined part of a drift alone made S or gamma worse in 60-65 % of the
// sweep's single-scan drift runs and halved none; core/sequence_refine identifies it from a
// plan with a closing pass or reversed traverses).
TEST_CASE("thermal drift: the identifiable combination is found, tau refined, not applied") {
  const double tau = 25.0;  // s; the scan lasts 128 s (4 traverses of 32 s)
  const std::uint64_t sd = 33;
  const auto c0 = make_refine_case(0.02, sd);
  const EffectContext ctx = scan_context(c0);
  Eigen::VectorXd p1 = Eigen::VectorXd::Zero(5);
  p1(2) = 1;
  const Eigen::MatrixXd J = reduce_columns(c0.cfg, ThermalDriftEffect(tau).jacobian(p1, ctx));
  const Eigen::MatrixXd Z = null_basis(check_identifiability(ResidualSpace(c0.cfg), J.leftCols(4)));
  Eigen::Vector4d a(0.0, 0.0, 100.0, 0.0);  // µm on configuration 3 (8 µm after the next line) ...
  a -= Z * (Z.transpose() * a);             // ... less what no scan can see
  std::printf("thermal drift injected: a = %g %g %g %g um, tau %g s\n", a(0), a(1), a(2), a(3),
              tau);
  const auto c = make_refine_case(0.02, sd, {}, [&](Eigen::MatrixXd& m, const Eigen::MatrixXd& t) {
    for (int i = 0; i < 4; ++i)
      m.col(i) += a(i) * (1.0 - (-t.col(i).array() / tau).exp()).matrix();
  });
  const auto r = run(c);
  print_steps("thermal drift (identifiable combination), sigma 0.02 um", r);
  REQUIRE(r.effects.size() >= 1);
  const auto* th = dynamic_cast<const ThermalDriftEffect*>(r.effects.front().get());
  REQUIRE(th != nullptr);
  // The estimate is the minimum-norm representative at the estimated τ̂ (the null space turns
  // with τ); the truth in that representation is a less its part in the null space at τ̂.
  const double tau_hat = th->tau_s(r.parameters.front());
  Eigen::VectorXd ph = Eigen::VectorXd::Zero(5);
  ph(2) = 1;
  const Eigen::MatrixXd Jh = reduce_columns(c0.cfg, ThermalDriftEffect(tau_hat).jacobian(ph, ctx));
  const Eigen::MatrixXd Zh =
      null_basis(check_identifiability(ResidualSpace(c0.cfg), Jh.leftCols(4)));
  Eigen::VectorXd p_true(5);
  p_true << a - Zh * (Zh.transpose() * a), tau - th->tau0_s();
  std::printf("  Gauss-Newton iterations %d\n", r.steps[1].gauss_newton_iterations);
  std::printf("  tau = %.3f +- %.3f s (truth %g s)\n", tau_hat, r.u_parameters.front()(4), tau);
  errsep::test::check_identified_not_applied(r, "thermal", p_true);
  CHECK(std::abs(th->tau_s(r.parameters.front()) - tau) < 2.0 * r.u_parameters.front()(4));
}

TEST_CASE("traverse: per-traverse S of degree 1..K leaves K directions, K-1 after linear drift") {
  const auto c0 = make_refine_case(0.02, 32);
  const EffectContext ctx = scan_context(c0);
  const ResidualSpace base(c0.cfg);
  const Eigen::MatrixXd Jd =
      reduce_columns(c0.cfg, DriftEffect().jacobian(Eigen::Vector4d::Zero(), ctx));
  for (int K : {1, 2, 3, 4, 5}) {
    const TraverseEffect tr(1, K);
    const Eigen::MatrixXd J =
        reduce_columns(c0.cfg, tr.jacobian(Eigen::VectorXd::Zero(tr.parameter_count()), ctx));
    const Identifiability id = check_identifiability(base, J);
    ResidualSpace with_drift(c0.cfg);
    with_drift.add(Jd);
    const Identifiability id_d = check_identifiability(with_drift, J);
    ResidualSpace with_traverse(c0.cfg);
    with_traverse.add(J);
    const int drift_after = check_identifiability(with_traverse, Jd).identifiable;
    std::printf(
        "degrees 1..%d: %d of %d identifiable (smallest relative sv %.3g), %d after the "
        "linear drift, linear drift after it %d\n",
        K, id.identifiable, id.parameters, id.relative_sv(id.identifiable - 1), id_d.identifiable,
        drift_after);
    CHECK(id.identifiable == K);
    CHECK(id_d.identifiable == K - 1);
    CHECK(drift_after == 0);  // degree 1 per traverse is the linear drift's column
  }
  // An offset of S or γ per traverse (degree 0) is invisible: e absorbs it.
  const TraverseEffect offset(0, 0);
  REQUIRE(offset.parameter_count() == 4);
  CHECK(check_identifiability(
            base, reduce_columns(c0.cfg, offset.jacobian(Eigen::VectorXd::Zero(4), ctx)))
            .identifiable == 0);
  // How much of a bow on one traverse (ΔS_3 = P2 + P3/2) one scan can see.
  const TraverseEffect tr;
  const Eigen::MatrixXd J =
      reduce_columns(c0.cfg, tr.jacobian(Eigen::VectorXd::Zero(tr.parameter_count()), ctx));
  const Eigen::MatrixXd Z = null_basis(check_identifiability(base, J));
  Eigen::VectorXd q = Eigen::VectorXd::Zero(tr.parameter_count());
  q(2 * 4 + 1) = 1.0;
  q(2 * 4 + 2) = 0.5;
  std::printf("a bow on traverse 3 alone: identifiable part %.3f of its parameter norm\n",
              distance_to_span(Z, q));
}

// Until stop 26 this asserted that S, gamma and f halve: the truth was built with no part in the
// null space and the determined part was applied.  The refine cannot know that part is zero: from
// one scan the rest of the effect is undetermined and could move S beyond u_S, so the effect is
// now reported "not identifiable from this plan" and carried in u_S, not applied (issue 16 item
// 1: applying the determined part of a drift alone made S or gamma worse in 60-65 % of the
// sweep's single-scan drift runs and halved none; core/sequence_refine identifies it from a
// plan with a closing pass or reversed traverses).
TEST_CASE("traverse: S not repeating between traverses is found, reported, not applied") {
  const std::uint64_t sd = 34;
  const auto c0 = make_refine_case(0.02, sd);
  const EffectContext ctx = scan_context(c0);
  const TraverseEffect tr;  // the library's: degrees 1..4
  const Eigen::MatrixXd J =
      reduce_columns(c0.cfg, tr.jacobian(Eigen::VectorXd::Zero(tr.parameter_count()), ctx));
  const Eigen::MatrixXd Z = null_basis(check_identifiability(ResidualSpace(c0.cfg), J));
  Eigen::VectorXd p = Eigen::VectorXd::Zero(tr.parameter_count());
  p(2 * 4 + 1) = 2.0;  // traverse 3: a bow of 2 µm (P2) ...
  p(2 * 4 + 2) = 1.0;  // ... and 1 µm of P3
  p -= Z * (Z.transpose() * p);
  std::printf("non-repeating S injected (identifiable part):");
  for (Eigen::Index j = 0; j < p.size(); ++j)
    std::printf(" %.3f", p(j));
  std::printf(" um\n");
  const auto c = make_refine_case(0.02, sd, {}, add_traverse_polynomials(p));
  const auto r = run(c);
  print_steps("non-repeating S (identifiable part), sigma 0.02 um", r);
  errsep::test::check_identified_not_applied(r, "traverse", p);
}

TEST_CASE("yaw (two axes): the lateral pair identifies a yaw Eqs. (10)-(27) cannot see") {
  Eigen::VectorXd c(6);
  c << 150.0, 60.0, 250.0, 0.0, -80.0, 40.0;  // µrad: up to ~0.5 mrad, a poor stage
  // Low noise: Eqs. (9), (24), (26) accumulate and amplify the reference sensors' noise (w error
  // ~0.1 µm rms at 2 nm, ~1 µm at 20 nm on this 25 x 25 grid), and the yaw's share of the w error
  // (~0.3 µm here) must stand well above that floor for "error halved" to be testable.
  TwoAxisSimOptions so;
  so.eddy_sensor.noise_sigma_um = 0.002;
  so.contact_sensor.noise_sigma_um = 0.002;
  so.seed = 41;
  YawRefineOptions o;
  const auto sim = simulate_two_axis_yaw(inclined_truth(), yaw_truth(c), so, o.geometry);
  const auto r = refine_two_axis_yaw(sim.two_axis.scan, sim.lateral, o);
  const double e_before = w_error_rms(r.before.w_um, sim.two_axis.w_um);
  const double e_after = w_error_rms(r.after.w_um, sim.two_axis.w_um);
  // The floor the correction can reach: the same scan with only the constant yaw c_00, which no
  // lateral pair can see (the workpiece's placement); on this inclined face it tilts w along x
  // through ψ_0·(x − x_axis)·∂w/∂y (±0.05 µm), above the joint estimate's noise floor (0.018 µm).
  Eigen::VectorXd c_const = Eigen::VectorXd::Zero(6);
  c_const(0) = c(0);
  const auto plain = simulate_two_axis_yaw(inclined_truth(), yaw_truth(c_const), so, o.geometry);
  const double e_plain =
      w_error_rms(separate_two_axis(plain.two_axis.scan, o.separation).w_um, plain.two_axis.w_um);
  std::printf("yaw, inclined workpiece (10, 5 um/mm), sigma 0.002 um\n  %s\n",
              r.brief_report().c_str());
  std::printf(
      "  w error (rms, mean removed): %.4f -> %.4f um (same scan with the constant yaw only: "
      "%.4f um)\n",
      e_before, e_after, e_plain);
  // c_0_0, the constant yaw, is not a parameter: it is the pair's zero offset (see header).
  REQUIRE(r.parameters_urad.size() == 5);
  for (Eigen::Index j = 0; j < 5; ++j)
    std::printf("  %-12s = %9.3f +- %.3f urad (truth %g)\n",
                r.parameter_names[static_cast<std::size_t>(j)].c_str(), r.parameters_urad(j),
                r.u_parameters_urad(j), c(j + 1));
  CHECK(r.yaw_added);
  CHECK(r.p_value < 1e-6);
  CHECK(r.identifiable == 5);
  for (Eigen::Index j = 0; j < 5; ++j) {
    INFO(r.parameter_names[static_cast<std::size_t>(j)]);
    CHECK(r.u_parameters_urad(j) > 0);
    CHECK(std::abs(r.parameters_urad(j) - c(j + 1)) < 3.0 * r.u_parameters_urad(j));
  }
  CHECK(r.rms_after_um < r.rms_before_um);
  // The residual after the fit is the lateral sensors' noise (σ̂ of ~1800 dof: ±2 % at 1 std).
  CHECK(r.sigma_after_um > 0.9 * so.eddy_sensor.noise_sigma_um);
  CHECK(r.sigma_after_um < 1.1 * so.eddy_sensor.noise_sigma_um);
  CHECK(e_after < 0.5 * e_before);
  CHECK(e_after < 1.5 * e_plain);
}

TEST_CASE("yaw (two axes): without yaw the lateral pair adds nothing in >= 95 % of runs") {
  YawRefineOptions o;
  int added = 0, runs = 0;
  for (double sigma : {0.1, 0.2, 0.3})
    for (std::uint64_t seed = 1; seed <= 10; ++seed) {
      TwoAxisSimOptions so;
      so.eddy_sensor.noise_sigma_um = sigma;
      so.contact_sensor.noise_sigma_um = sigma;
      so.seed = 500 + seed;
      const auto sim = simulate_two_axis_yaw(inclined_truth(), yaw_truth(Eigen::VectorXd::Zero(6)),
                                             so, o.geometry);
      const auto r = refine_two_axis_yaw(sim.two_axis.scan, sim.lateral, o);
      ++runs;
      if (r.yaw_added) {
        ++added;
        std::printf("  sigma %.1f seed %llu: %s\n", sigma, static_cast<unsigned long long>(seed),
                    r.brief_report().c_str());
      }
    }
  std::printf("no yaw: added in %d of %d runs\n", added, runs);
  CHECK(added <= runs / 20);
}

TEST_CASE("yaw (two axes): at the paper's sizes its effect on w is far below the noise") {
  // ψ of 30 µrad varying over the travel, the example stage's workpiece (slopes <= 0.4 um/mm).
  Eigen::VectorXd c(6);
  c << 0.0, 10.0, 30.0, 0.0, -10.0, 0.0;
  TwoAxisSimOptions so;  // noise-free
  YawGeometry g;
  const auto with = simulate_two_axis_yaw(example_two_axis_truth(), yaw_truth(c), so, g);
  const auto without =
      simulate_two_axis_yaw(example_two_axis_truth(), yaw_truth(Eigen::VectorXd::Zero(6)), so, g);
  TwoAxisOptions o;
  const double d = w_error_rms(separate_two_axis(with.two_axis.scan, o).w_um,
                               separate_two_axis(without.two_axis.scan, o).w_um);
  std::printf("paper-sized yaw (<= 40 urad): w changes by %.2e um rms (sensor noise 0.16 um)\n", d);
  CHECK(d < 0.01);
}

TEST_CASE("yaw (two axes): the paper's reference sensors alone cannot see it") {
  // Sensors 1, 2 (Eqs. 11, 12, 16, 17): per point ez_x and roll_x are free, which leaves the
  // differences between the scans, Eq. (4); reference X is one piece, so r_k(x + d) − r_k(x) is
  // shared by every row y_j and the row mean is its least-squares fit.  What is left of the yaw's
  // slope terms after that projection is all this redundancy can ever see of it: its squared
  // norm over σ² is the non-centrality of any test for it.
  Eigen::VectorXd c(6);
  c << 150.0, 60.0, 250.0, 0.0, -80.0, 40.0;  // the exaggerated yaw of the test above
  TwoAxisSimOptions so;                       // noise-free: the yaw's own signal
  YawGeometry g;
  const auto with = simulate_two_axis_yaw(inclined_truth(), yaw_truth(c), so, g);
  const auto without =
      simulate_two_axis_yaw(inclined_truth(), yaw_truth(Eigen::VectorXd::Zero(6)), so, g);
  const TwoAxisScan &a = with.two_axis.scan, &b = without.two_axis.scan;
  double seen = 0, raw = 0;
  for (const auto& [s1, s2, t1, t2] :
       {std::tuple{&a.s1_1_um, &a.s1_2_um, &b.s1_1_um, &b.s1_2_um},
        std::tuple{&a.s2_1_um, &a.s2_2_um, &b.s2_1_um, &b.s2_2_um}}) {
    const Eigen::MatrixXd z1 = *s1 - *t1, z2 = *s2 - *t2;  // the yaw's terms in the readings
    raw += z1.squaredNorm() + z2.squaredNorm();
    Eigen::MatrixXd dz = (z1 - z2) / std::sqrt(2.0);  // Eq. (4) rows, orthonormal
    for (Eigen::Index i = 0; i < dz.rows(); ++i)
      dz.row(i).array() -= dz.row(i).mean();  // shared r_k(x + d) − r_k(x)
    seen += dz.squaredNorm();
  }
  const double sigma = 0.16;  // µm, the paper's eddy-current sensors (section 3.1)
  std::printf(
      "paper's sensors 1, 2, yaw up to 0.5 mrad: yaw terms %.3g um rms in the readings, "
      "visible part %.3g um (non-centrality %.3g at sigma %.2f um)\n",
      std::sqrt(raw / (4.0 * a.s1_1_um.size())), std::sqrt(seen), seen / (sigma * sigma), sigma);
  CHECK(seen / (sigma * sigma) < 1.0);
}

TEST_CASE("yaw (two axes): a constant yaw is the lateral pair's zero offset, not seen") {
  Eigen::VectorXd c = Eigen::VectorXd::Zero(6);
  c(0) = 300.0;  // µrad, constant: the workpiece placed rotated on the table
  TwoAxisSimOptions so;
  so.eddy_sensor.noise_sigma_um = 0.002;
  so.contact_sensor.noise_sigma_um = 0.002;
  so.seed = 43;
  YawRefineOptions o;
  const auto sim = simulate_two_axis_yaw(inclined_truth(), yaw_truth(c), so, o.geometry);
  const auto r = refine_two_axis_yaw(sim.two_axis.scan, sim.lateral, o);
  std::printf("constant yaw 300 urad: %s\n", r.brief_report().c_str());
  CHECK_FALSE(r.yaw_added);
  // The base model (g, e_y, zero offset) explains the readings down to the noise.
  CHECK(r.sigma_before_um < 1.1 * so.eddy_sensor.noise_sigma_um);
}

// The identifiable part of the non-repeating S above at the paper's noise levels, four seeds each:
// the error it causes in S, γ, f must halve over the seeds (against the truth the noise floor of
// the separation dominates at 0.3 µm: S 0.9 -> 0.8-1.6 µm, the 16 parameters' uncertainty carried
// into S as large as what the effect did).
//
// Not here, because it does not hold: the thermal drift (identifiable part, τ = 25 s) at σ = 0.1
// µm is found in 4 of 4 seeds, but the error it causes in S does not halve over them (RMS 1.56 ->
// 1.53 µm; γ 95.6 -> 50.0 µrad) and τ's standardised error reaches -3.7; at 0.3 µm one seed takes
// the linear drift instead and one ends with S 1.7 -> 5.2 µm.  τ is weakly determined at that noise
// (relative singular value of the amplitude direction 0.21) and the loop has no guard against a
// correction whose uncertainty exceeds the error it removes.
TEST_CASE("realistic noise: non-repeating S at sigma 0.1 and 0.3 um", "[sweep]") {
  const auto c0 = make_refine_case(0.1, 1);
  const EffectContext ctx = scan_context(c0);
  const TraverseEffect tr;
  const Eigen::MatrixXd J =
      reduce_columns(c0.cfg, tr.jacobian(Eigen::VectorXd::Zero(tr.parameter_count()), ctx));
  const Eigen::MatrixXd Z = null_basis(check_identifiability(ResidualSpace(c0.cfg), J));
  Eigen::VectorXd p = Eigen::VectorXd::Zero(tr.parameter_count());
  p(2 * 4 + 1) = 2.0;
  p(2 * 4 + 2) = 1.0;
  p -= Z * (Z.transpose() * p);
  // 40 seeds at 0.1 µm (160 decorrelated z).  Seeds 1-4 alone gave 4 of 16 beyond 2 against a
  // 99 % allowance of 3, and seeds 1-16 8 of 64 against 7: draws of 1 % and 3 %.  Over seeds
  // 301-900 the z have RMS 1.007 and 4.7 % beyond 2, as a t with ~52 dof should (5.1 %), so the
  // count is made on a sample large enough not to hang on a few seeds.  At 0.3 µm the same seeds
  // give the same z (the error is linear in the noise): four seeds, for the error check only.
  // The halving of the error is no longer asserted (stop 26, issue 16 item 1): the traverse
  // effect is not identifiable from one scan's plan and is carried in u_S, not applied; what is
  // asserted is that it is found, its determined part within its uncertainty, and no seed worse
  // beyond its u.
  for (const auto& [sigma, seeds] : {std::pair{0.1, 40}, std::pair{0.3, 4}})
    errsep::test::check_realistic(
        "non-repeating S (identifiable part of a 2 um P2 + 1 um P3 on traverse 3)", "traverse",
        sigma, seeds, 0,
        [&](double sg, std::uint64_t seed) {
          return make_refine_case(sg, seed, {}, add_traverse_polynomials(p));
        },
        [&](const ModelEffect&) { return p; }, /*count_z=*/sigma < 0.2, {}, /*halved=*/false);
}

// The redundant equations of the displacement method (core/displacement_residuals.hpp) on
// simulated scans: the noise level they imply against the simulated σ, their whiteness on clean
// data over many seeds, an effect the model lacks (found and reported), and the effects the
// redundancy cannot see (their residual is exactly zero).  Noise as the paper measured it
// (section 3.1): eddy-current reference sensors σ_se = 0.16 µm, contact sensor σ_sc = 0.29 µm.
#include <Eigen/Dense>
#include <boost/math/distributions/chi_squared.hpp>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <string>

#include "errsep/core/displacement_method.hpp"
#include "errsep/core/displacement_residuals.hpp"
#include "errsep/core/displacement_simulation.hpp"
#include "errsep/core/two_axis_displacement.hpp"

using namespace errsep::core;

namespace {

constexpr double kSigmaEddy = 0.16, kSigmaContact = 0.29;

/// Two-sided interval of σ̂/σ for dof degrees of freedom at probability p (χ²_dof / dof).
std::pair<double, double> ratio_interval(int dof, double p) {
  const boost::math::chi_squared chi(dof);
  return {std::sqrt(boost::math::quantile(chi, 0.5 * (1 - p)) / dof),
          std::sqrt(boost::math::quantile(chi, 0.5 * (1 + p)) / dof)};
}

OneAxisSimOptions one_axis_options(std::uint64_t seed) {
  OneAxisSimOptions so;  // Fig. 5: 120 mm at 5 mm, d = 5 mm, 25 samples
  so.workpiece_sensor.noise_sigma_um = kSigmaContact;
  so.reference_sensor.noise_sigma_um = kSigmaEddy;
  so.seed = seed;
  return so;
}

OneAxisRun run_of(const OneAxisSimData& s) {
  return {s.s1_1_um, s.s2_1_um, s.s2_2_um, s.s1_2_um};
}

TwoAxisSimOptions two_axis_options(std::uint64_t seed) {
  TwoAxisSimOptions so;  // 25 x 25 at 5 mm, the paper's lever arms
  so.eddy_sensor.noise_sigma_um = kSigmaEddy;
  so.contact_sensor.noise_sigma_um = kSigmaContact;
  so.record_s0_scan2 = true;
  so.seed = seed;
  return so;
}

/// Centred w error RMS (w is known up to a constant).
double w_error_rms(const Eigen::MatrixXd& w_est, const Eigen::MatrixXd& w_true) {
  Eigen::MatrixXd e = w_est - w_true;
  e.array() -= e.mean();
  return std::sqrt(e.squaredNorm() / static_cast<double>(e.size()));
}

/// RMS of e after removing its least-squares line over the sample index.
double detrended_rms(const Eigen::VectorXd& e) {
  const Eigen::Index n = e.size();
  Eigen::MatrixXd A(n, 2);
  A.col(0).setOnes();
  A.col(1) = Eigen::VectorXd::LinSpaced(n, 0.0, static_cast<double>(n - 1));
  const Eigen::VectorXd c = A.colPivHouseholderQr().solve(e);
  return std::sqrt((e - A * c).squaredNorm() / static_cast<double>(n));
}

}  // namespace

TEST_CASE("one axis, Eqs. (1)-(3) only: exactly determined, no residual, said so") {
  const auto sim = simulate_one_axis(haramiishi2024_fig5_truth(), one_axis_options(1));
  const auto r = displacement_residuals_one_axis(
      sim.x_mm, {OneAxisRun{sim.s1_1_um, sim.s2_1_um, sim.s2_2_um, {}}});
  std::printf("%s\n", r.brief_report().c_str());
  CHECK(r.families.empty());
  CHECK(r.dof == 0);
  CHECK(r.white);
  CHECK_THAT(r.note, Catch::Contains("exactly determined"));
}

TEST_CASE("one axis: the workpiece repeat's sigma_hat and whiteness over 40 clean seeds") {
  // S1_2 - S1_1 has variance 2·σ_sc², dof n - 1 = 24 per seed.  Each σ̂ must lie in its 99 %
  // χ² interval in all but a binomial allowance (P(more than 3 of 40 outside) < 0.001), and the
  // pooled σ̂ (dof 960) in its 99.9 % interval; white in >= 95 % of the seeds (α = 0.01).
  const int seeds = 40;
  int outside = 0, white = 0, dof = 0;
  double rss_c = 0;
  for (int s = 1; s <= seeds; ++s) {
    const auto sim = simulate_one_axis(haramiishi2024_fig5_truth(),
                                       one_axis_options(static_cast<std::uint64_t>(1000 + s)));
    const auto r = displacement_residuals_one_axis(sim.x_mm, {run_of(sim)});
    REQUIRE(r.families.size() == 1);
    const auto& f = r.families[0];
    REQUIRE(f.kind == RedundancyKind::workpiece_repeat);
    REQUIRE(f.dof == 24);
    const auto [lo, hi] = ratio_interval(f.dof, 0.99);
    if (f.sigma_um < lo * kSigmaContact || f.sigma_um > hi * kSigmaContact) ++outside;
    white += f.whiteness.white ? 1 : 0;
    dof += f.dof;
    rss_c += f.rss_um2 / f.channels[0].variance_factor;
  }
  const double pooled = std::sqrt(rss_c / dof);
  const auto [lo, hi] = ratio_interval(dof, 0.999);
  std::printf(
      "one axis, workpiece repeat, sigma_sc %.2f um: pooled sigma_hat %.4f um (dof %d, 99.9 %% "
      "interval %.4f-%.4f), %d of %d seeds outside their 99 %% interval, white in %d of %d\n",
      kSigmaContact, pooled, dof, lo * kSigmaContact, hi * kSigmaContact, outside, seeds, white,
      seeds);
  CHECK(pooled > lo * kSigmaContact);
  CHECK(pooled < hi * kSigmaContact);
  CHECK(outside <= 3);
  CHECK(white >= 38);
}

TEST_CASE("one axis: repeated runs give each sensor's sigma_hat, the separation uses their mean") {
  // Three runs (independent noise); per channel dof n(R - 1) = 50.
  std::vector<OneAxisRun> runs;
  std::vector<OneAxisSimData> sims;
  for (std::uint64_t s = 1; s <= 3; ++s) {
    sims.push_back(simulate_one_axis(haramiishi2024_fig5_truth(), one_axis_options(70 + s)));
    runs.push_back(run_of(sims.back()));
  }
  const auto r = displacement_residuals_one_axis(sims[0].x_mm, runs);
  std::printf("%s\n", r.brief_report().c_str());
  REQUIRE(r.families.size() == 2);
  const auto& rep = r.families[1];
  REQUIRE(rep.kind == RedundancyKind::repeated_runs);
  REQUIRE(rep.channels.size() == 4);
  const auto [lo, hi] = ratio_interval(50, 0.999);
  for (const auto& ch : rep.channels) {
    INFO(ch.name);
    CHECK(ch.dof == 50);
    const double truth = ch.sensor == 1 ? kSigmaContact : kSigmaEddy;
    CHECK(ch.sigma_um > lo * truth);
    CHECK(ch.sigma_um < hi * truth);
  }
  // The workpiece repeat on the run means: variance factor 2/R.
  CHECK(r.families[0].channels[0].variance_factor == Approx(2.0 / 3.0));
  const auto mean = mean_of_runs(runs);
  CHECK(mean.s2_1_um(4) ==
        Approx((runs[0].s2_1_um(4) + runs[1].s2_1_um(4) + runs[2].s2_1_um(4)) / 3.0));
  CHECK_THROWS_WITH(displacement_residuals_one_axis(sims[0].x_mm.head(10), runs),
                    Catch::Contains("run 1: every scan must have 10 readings"));
}

TEST_CASE("one axis: a table that moves during scan 2 is seen by the workpiece repeat") {
  // The table rises by h(t) = A (1 - exp(-t/τ)) during scan 2 (t from its start, 1 s per
  // sample, τ = 8 s): both sensors see it (Eqs. 1, 3 with m + h), so every difference of Eq. (4)
  // carries h(x_k) and Eq. (9) sums it into r: r, m and w are off by Σ h, up to ~n·A (its
  // constant part a tilt, the rest not); S1_2 - S1_1 = h.  With 25 samples and the difference's
  // noise σ_sc·√2 = 0.41 µm the whiteness test has little power for small A (measured over 40
  // seeds at τ = 8 s: A = 1 µm found in 2, 2 µm in 20, 3 µm in 39, 4 µm in 40), although A = 1
  // µm already costs ~5 µm of w: this redundancy is a weak guard on one axis.  Asserted at 4 µm.
  const double A = 4.0, tau = 8.0;
  int found = 0, white_clean = 0;
  const int seeds = 10;
  double w_err_clean = 0, w_err_moved = 0, w_tilt_clean = 0, w_tilt_moved = 0;
  for (int s = 1; s <= seeds; ++s) {
    const auto sim = simulate_one_axis(haramiishi2024_fig5_truth(),
                                       one_axis_options(static_cast<std::uint64_t>(200 + s)));
    OneAxisRun clean = run_of(sim), moved = clean;
    for (Eigen::Index k = 0; k < sim.x_mm.size(); ++k) {
      const double h = A * (1.0 - std::exp(-static_cast<double>(k) / tau));
      moved.s1_2_um(k) += h;
      moved.s2_2_um(k) += h;
    }
    const auto rc = displacement_residuals_one_axis(sim.x_mm, {clean});
    const auto rm = displacement_residuals_one_axis(sim.x_mm, {moved});
    white_clean += rc.white ? 1 : 0;
    found += rm.white ? 0 : 1;
    if (s == 1)
      std::printf("table moving during scan 2 (seed 1):\n%s\n", rm.brief_report().c_str());
    DisplacementOptions o;
    const auto wc = separate_displacement(clean.s1_1_um, clean.s2_1_um, clean.s2_2_um, o).w_um;
    const auto wm = separate_displacement(moved.s1_1_um, moved.s2_1_um, moved.s2_2_um, o).w_um;
    w_err_clean += std::pow(w_error_rms(wc, sim.w_um), 2);
    w_err_moved += std::pow(w_error_rms(wm, sim.w_um), 2);
    w_tilt_clean += std::pow(detrended_rms(wc - sim.w_um), 2);
    w_tilt_moved += std::pow(detrended_rms(wm - sim.w_um), 2);
  }
  std::printf(
      "table moving during scan 2 (A %.1f um, tau %.0f s): not white in %d of %d seeds (clean: "
      "white in %d of %d); w error rms %.3f um -> %.3f um (best-fit line removed: %.3f -> %.3f "
      "um)\n",
      A, tau, found, seeds, white_clean, seeds, std::sqrt(w_err_clean / seeds),
      std::sqrt(w_err_moved / seeds), std::sqrt(w_tilt_clean / seeds),
      std::sqrt(w_tilt_moved / seeds));
  CHECK(found >= 9);
  CHECK(white_clean >= 9);
}

TEST_CASE("two axes: sigma_hat of the reference pieces and the workpiece repeat, 40 clean seeds",
          "[sweep]") {
  // Reference pieces: dof 2·25·24 + 2·25·24 = 2400 per seed, one σ for the four eddy-current
  // sensors; workpiece repeat (sensor 0 read in both scans): dof 624.  Each seed's σ̂ in its
  // 99.9 % interval (40 seeds x 2: expected 0.08 outside), whiteness of all families together
  // (Bonferroni over the two) in >= 95 % of the seeds.
  const int seeds = 40;
  int white = 0, outside = 0;
  for (int s = 1; s <= seeds; ++s) {
    const auto sim = simulate_two_axis(example_two_axis_truth(),
                                       two_axis_options(static_cast<std::uint64_t>(300 + s)));
    const auto r = displacement_residuals_two_axis({sim.scan});
    REQUIRE(r.families.size() == 2);
    const auto& ref = r.families[0];
    const auto& wp = r.families[1];
    REQUIRE(ref.kind == RedundancyKind::reference_pieces);
    REQUIRE(ref.dof == 2400);
    REQUIRE(wp.kind == RedundancyKind::workpiece_repeat);
    REQUIRE(wp.dof == 624);
    const auto [lr, hr] = ratio_interval(ref.dof, 0.999);
    const auto [lw, hw] = ratio_interval(wp.dof, 0.999);
    if (ref.sigma_um < lr * kSigmaEddy || ref.sigma_um > hr * kSigmaEddy) ++outside;
    if (wp.sigma_um < lw * kSigmaContact || wp.sigma_um > hw * kSigmaContact) ++outside;
    white += r.white ? 1 : 0;
    if (s == 1) std::printf("two axes, clean (seed 301):\n%s\n", r.brief_report().c_str());
    if (!r.white) std::printf("  seed %d not white:\n%s\n", 300 + s, r.brief_report().c_str());
  }
  std::printf("two axes clean: %d of %d seeds white, %d of %d sigma_hat outside 99.9 %%\n", white,
              seeds, outside, 2 * seeds);
  CHECK(outside <= 1);
  CHECK(white >= 38);
}

TEST_CASE("two axes: a thermal drift of the paper's size is found, what cannot be seen is zero",
          "[sweep]") {
  // First-order thermal drift of the eddy-current sensors, δ(t) = A (1 - exp(-t/τ)) from the
  // start of scan 1 (1 s per point, 625 s per scan), A = 0.5 µm, τ = 600 s: the range the paper
  // measured over 10 min (Fig. 14: -0.3 to 0.2 µm).  D_k picks up δ(t + 625 s) - δ(t), which
  // changes from row to row; Eq. (9) sums it into r.
  const double A = 0.5, tau = 600.0;
  const auto truth = example_two_axis_truth();
  int found = 0;
  const int seeds = 5;
  double e_clean = 0, e_drift = 0;
  std::string p_values;
  for (int s = 1; s <= seeds; ++s) {
    const auto so = two_axis_options(static_cast<std::uint64_t>(400 + s));
    const auto sim = simulate_two_axis(truth, so);
    TwoAxisScan drift = sim.scan;
    const int nx = so.nx, ny = so.ny;
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const double t1 = j * nx + i, t2 = nx * ny + t1;
        const double d1 = A * (1 - std::exp(-t1 / tau)), d2 = A * (1 - std::exp(-t2 / tau));
        for (auto* m : {&drift.s1_1_um, &drift.s2_1_um, &drift.s3_1_um, &drift.s4_1_um})
          (*m)(i, j) += d1;
        for (auto* m : {&drift.s1_2_um, &drift.s2_2_um, &drift.s3_2_um, &drift.s4_2_um})
          (*m)(i, j) += d2;
      }
    const auto r = displacement_residuals_two_axis({drift});
    found += r.white ? 0 : 1;
    p_values += (s > 1 ? ", " : "") + std::to_string(r.families[0].whiteness.p_value);
    if (s == 1) std::printf("thermal drift (seed 401):\n%s\n", r.brief_report().c_str());
    CHECK_FALSE(r.families[0].whiteness.white);  // the reference pieces' family itself
    const TwoAxisOptions o;
    e_clean += std::pow(w_error_rms(separate_two_axis(sim.scan, o).w_um, sim.w_um), 2);
    e_drift += std::pow(w_error_rms(separate_two_axis(drift, o).w_um, sim.w_um), 2);
  }
  // The combined p-value is a rank among 1000 (data + 999 draws): 0.001 is its floor, α/2 = 0.005
  // the family's level.
  std::printf(
      "thermal drift A %.1f um tau %.0f s: not white in %d of %d (reference pieces p = "
      "%s); w error rms %.3f -> %.3f um\n",
      A, tau, found, seeds, p_values.c_str(), std::sqrt(e_clean / seeds),
      std::sqrt(e_drift / seeds));
  CHECK(found == seeds);

  // Noise-free: the residual of each invisible effect is zero (to rounding), the drift's is not.
  TwoAxisSimOptions so;
  so.record_s0_scan2 = true;
  auto max_residual = [](const DisplacementResiduals& r) {
    double m = 0;
    for (const auto& f : r.families)
      for (const auto& ch : f.channels)
        m = std::max(m, ch.residual_um.cwiseAbs().maxCoeff());
    return m;
  };
  const auto base = simulate_two_axis(truth, so);
  so.eddy_sensor.drift_um_per_s = 0.002;  // linear drift, 1.25 µm per scan
  so.contact_sensor.drift_um_per_s = 0.002;
  so.displacement_bias_mm = 0.3;  // traverse d off by 0.3 mm
  const auto lin = simulate_two_axis(truth, so);
  TwoAxisScan gain = base.scan;  // a 2 % gain error of sensor 1, the same in both scans
  gain.s1_1_um *= 1.02;
  gain.s1_2_um *= 1.02;
  const double r_lin = max_residual(displacement_residuals_two_axis({lin.scan}));
  const double r_gain = max_residual(displacement_residuals_two_axis({gain}));
  std::printf("noise-free residual max: linear drift + d error %.2e um, gain %.2e um\n", r_lin,
              r_gain);
  CHECK(r_lin < 1e-9);
  CHECK(r_gain < 1e-9);
  // ...while a gain that changes between the scans is seen (it scales m, which differs by row).
  TwoAxisScan gain2 = base.scan;
  gain2.s1_2_um *= 1.02;
  CHECK(max_residual(displacement_residuals_two_axis({gain2})) > 1e-3);
}

TEST_CASE("two axes: time order, repeated runs and bad input") {
  auto so = two_axis_options(77);
  so.nx = 9;
  so.ny = 7;
  const auto a = simulate_two_axis(example_two_axis_truth(), so);
  so.seed = 78;
  const auto b = simulate_two_axis(example_two_axis_truth(), so);
  // The default order is the raster x fastest: giving it explicitly changes nothing.
  Eigen::MatrixXd t(9, 7);
  for (int j = 0; j < 7; ++j)
    for (int i = 0; i < 9; ++i)
      t(i, j) = j * 9 + i;
  const auto r0 = displacement_residuals_two_axis({a.scan});
  const auto r1 = displacement_residuals_two_axis({a.scan}, {}, t);
  CHECK(r0.families[0].channels[0].residual_um.isApprox(r1.families[0].channels[0].residual_um));
  CHECK(r0.families[0].whiteness.p_value == r1.families[0].whiteness.p_value);
  // Two runs: reference pieces and workpiece repeat on the mean (factor 2/2), plus the runs.
  const auto r2 = displacement_residuals_two_axis({a.scan, b.scan});
  REQUIRE(r2.families.size() == 3);
  CHECK(r2.families[0].channels[0].variance_factor == Approx(1.0));
  CHECK(r2.families[2].kind == RedundancyKind::repeated_runs);
  CHECK(r2.families[2].channels.size() == 10);
  CHECK(r2.families[2].dof == 10 * 63);
  // Bad input names what is wrong.
  TwoAxisScan bad = a.scan;
  bad.s3_2_um(2, 3) = std::nan("");
  CHECK_THROWS_WITH(displacement_residuals_two_axis({bad}),
                    Catch::Contains("non-finite value in run 1 s3_2"));
  bad = b.scan;
  bad.s4_1_um.resize(9, 6);
  CHECK_THROWS_WITH(displacement_residuals_two_axis({a.scan, bad}),
                    Catch::Contains("run 2 s4_1 is 9x6, grid is 9x7"));
}

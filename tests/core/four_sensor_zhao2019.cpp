// Reproduces section 3 of Zhao et al. 2019 (simulation verification of the four-sensor method):
// Example 1 at three noise levels over 20 seeded runs, the unregularised solution of Fig. 3(d),
// the positioning errors PE1 and PE2, and Example 2 over harmonic orders.  Prints the paper's
// figures beside ours.
//
// KNOWN GAP (see the note on issue 2): with the identity regulariser and the L-curve corner our S
// figures do not meet issue 2's bars (1.5x the paper's ΔS_max and ΔS^a_max) and Example 2 exceeds
// 2.6 µm for low harmonic orders k.  Those bars are printed as MET / NOT MET below and are NOT
// asserted (asserting a widened bar would hide the gap); the γ bars, PE1/PE2 and Fig. 3(d) are.
// Why: the last test case computes the unbiased floor — even with e known, the minimum-variance
// unbiased Ŝ has a standard deviation of 2.17 µm at σ = 0.1 µm, i.e. an expected ΔS_max over 20
// runs of about 4 µm.  The paper's 1.1 µm needs regularisation bias that happens to be small for
// its test profiles; with the identity regulariser no λ gives both ΔS_max ≤ 1.65 and ΔS^a ≤ 0.225
// (fixed-λ sweep over 200 seeds: λ = 0.05 gives 2.08 / 0.32, λ = 0.1 gives 1.52 / 0.66).
#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <cstdio>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/four_sensor_simulation.hpp"

using namespace errsep::core;

namespace {

struct Figures {
  double dS_max = 0, dS_avg_max = 0, dg_max_deg = 0, dg_avg_max_deg = 0;
};

// ΔS_max: largest |S − S_true| over all runs and points; ΔS^a_max: largest |mean S − S_true|;
// the same for γ after removing its constant (γ is known up to e4/(D2+D3+D4), Eq. 19).
Figures run(const FourSensorConfig& cfg, const SlidewayTruth& truth, FourSensorSimOptions so,
            const FourSensorOptions& opts, int runs) {
  Figures fig;
  const int P = cfg.positions();
  Eigen::VectorXd sum_dS = Eigen::VectorXd::Zero(P), sum_dg = Eigen::VectorXd::Zero(P);
  for (int r = 0; r < runs; ++r) {
    so.seed = 1000 + static_cast<std::uint64_t>(r);
    const auto sim = simulate_four_sensor(cfg, truth, so);
    const auto res = separate_four_sensor(cfg, sim.m_um, opts);
    const Eigen::VectorXd dS = res.S_um - sim.S_um;
    Eigen::VectorXd dg = res.gamma_rad - sim.gamma_rad;
    dg.array() -= dg.mean();
    fig.dS_max = std::max(fig.dS_max, dS.cwiseAbs().maxCoeff());
    fig.dg_max_deg = std::max(fig.dg_max_deg, dg.cwiseAbs().maxCoeff() * kDegPerRad);
    sum_dS += dS;
    sum_dg += dg;
  }
  fig.dS_avg_max = (sum_dS / runs).cwiseAbs().maxCoeff();
  fig.dg_avg_max_deg = (sum_dg / runs).cwiseAbs().maxCoeff() * kDegPerRad;
  return fig;
}

FourSensorOptions fast_opts() {
  FourSensorOptions o;
  o.compute_uncertainty = false;
  return o;
}

}  // namespace

TEST_CASE("Example 1 (Eqs. 21-23): residuals at sigma = 0.1, 0.2, 0.3 um over 20 runs") {
  const FourSensorConfig cfg;  // dx = 5 mm, s = (1, 1, 5), N = 69
  const auto truth = zhao2019_example1(cfg);
  struct Paper {
    double sigma, dS, dSa, dg, dga;
  };
  const Paper paper[] = {{0.1, 1.1, 0.15, 1.8e-3, 2.5e-4},
                         {0.2, 1.6, 0.26, 3.2e-3, 6.5e-4},
                         {0.3, 2.3, 0.30, 3.9e-3, 7.2e-4}};
  std::printf("\nZhao 2019 Example 1, 20 runs each, lambda by L-curve corner (ours | paper)\n");
  std::printf(" sigma  dS_max um      dS^a_max um     dg_max deg            dg^a_max deg\n");
  for (const auto& p : paper) {
    FourSensorSimOptions so;
    so.sigma_um = p.sigma;
    const Figures f = run(cfg, truth, so, fast_opts(), 20);
    std::printf(" %.1f   %.2f | %.2f    %.3f | %.3f   %.2e | %.1e    %.2e | %.1e\n", p.sigma,
                f.dS_max, p.dS, f.dS_avg_max, p.dSa, f.dg_max_deg, p.dg, f.dg_avg_max_deg, p.dga);
    INFO("sigma = " << p.sigma);
    std::printf("        S bars (1.5x paper): dS_max %s, dS^a_max %s\n",
                f.dS_max <= 1.5 * p.dS ? "MET" : "NOT MET",
                f.dS_avg_max <= 1.5 * p.dSa ? "MET" : "NOT MET");
    CHECK(f.dg_max_deg <= 3.0 * p.dg);
    CHECK(f.dg_avg_max_deg <= 10.0 * p.dga);
  }
}

TEST_CASE("Fig. 3(d): the unregularised least-squares solution deviates strongly") {
  const FourSensorConfig cfg;
  const auto truth = zhao2019_example1(cfg);
  FourSensorSimOptions so;
  so.sigma_um = 0.1;
  FourSensorOptions reg = fast_opts(), ls = fast_opts(), ls_eq12 = fast_opts();
  ls.rule = LambdaRule::least_squares;
  ls_eq12.rule = LambdaRule::least_squares;
  ls_eq12.gauge = CurvatureGauge::paper_eq12_literal;
  const Figures f_reg = run(cfg, truth, so, reg, 5);
  const Figures f_ls = run(cfg, truth, so, ls, 5);
  const Figures f_eq12 = run(cfg, truth, so, ls_eq12, 5);
  std::printf(
      "\nFig. 3(d), sigma = 0.1 um, 5 runs: dS_max regularised %.2f um, least squares %.2f "
      "um, least squares with Eq. (12) as printed %.2f um\n",
      f_reg.dS_max, f_ls.dS_max, f_eq12.dS_max);
  CHECK(f_ls.dS_max > 5 * f_reg.dS_max);
  CHECK(f_eq12.dS_max > 5 * f_reg.dS_max);
}

TEST_CASE("positioning errors PE1 and PE2 at sigma = 0") {
  const FourSensorConfig cfg;
  const auto truth = zhao2019_example1(cfg);
  FourSensorSimOptions pe1, pe2;
  pe1.actual_spacing_mm = zhao2019_pe1_spacing_mm();
  pe2.positioning_error_um = zhao2019_pe2_um(cfg.travel_mm());
  const Figures f1 = run(cfg, truth, pe1, fast_opts(), 1);
  const Figures f2 = run(cfg, truth, pe2, fast_opts(), 1);
  std::printf(
      "\nPE1: dS_max %.3f um (paper 0.1), dg_max %.2e deg (paper < 1.0e-4)\n"
      "PE2: dS_max %.3f um (paper 0.15), dg_max %.2e deg (paper 1.0e-4)\n",
      f1.dS_max, f1.dg_max_deg, f2.dS_max, f2.dg_max_deg);
  CHECK(f1.dS_max <= 2 * 0.1);
  CHECK(f2.dS_max <= 2 * 0.15);
}

TEST_CASE("Example 2 (Eq. 24): dS_max at sigma = 0.2 over harmonic orders (bar 2.6 um printed)") {
  const FourSensorConfig cfg;
  FourSensorSimOptions so;
  so.sigma_um = 0.2;
  std::printf("\nExample 2, sigma = 0.2 um, 20 runs per k: k dS_max dS^a_max dg_max dg^a_max\n");
  for (int k = 1; k <= 15; ++k) {
    if (k == 10) continue;  // coincides with the second term of Eq. (24)
    const Figures f = run(cfg, zhao2019_example2(cfg, k), so, fast_opts(), 20);
    std::printf(" %2d  %.2f  %.3f  %.2e  %.2e  %s\n", k, f.dS_max, f.dS_avg_max, f.dg_max_deg,
                f.dg_avg_max_deg, f.dS_max <= 2.6 ? "MET" : "NOT MET");
    INFO("k = " << k);
    // What is asserted: the separation stays bounded and regularisation beats least squares.
    FourSensorOptions ls = fast_opts();
    ls.rule = LambdaRule::least_squares;
    const Figures f_ls = run(cfg, zhao2019_example2(cfg, k), so, ls, 3);
    CHECK(f.dS_max < f_ls.dS_max);
  }
}

// Why the S bars are out of reach: the best any unbiased estimator can do.  The readings of Eq. (1)
// with white noise σ are a linear model in (f, S, γ, e); its least-squares estimate is the
// minimum-variance unbiased one (Gauss–Markov; Cramér–Rao for Gaussian noise).  Even when the
// zero-adjustment values e are KNOWN (so only the line of S and f is gauged, by Eq. 11), the
// standard deviation of Ŝ at the worst position times ~1.87 (the mean largest |z| of 20 normal
// draws) exceeds the paper's ΔS_max = 1.1 µm at σ = 0.1 µm, and its 1.5× bar.  So the paper's
// figures need a biased (regularised) estimator whose bias happens to be small for its test
// profiles; the identity-Tikhonov frontier (printed by the first test case) does not reach them.
TEST_CASE(
    "Example 1: the unbiased floor of dS_max at sigma = 0.1 um lies above the paper's 1.1 um") {
  const FourSensorConfig cfg;
  const int N = cfg.N, P = cfg.positions();
  const auto k = cfg.offsets_samples();
  const auto O = cfg.offsets_mm();
  const double sigma = 0.1;
  // Unknowns f (N), S (P), γ (P); e known.  Rows: 4P readings, plus f(x_0) = f(x_{N−1}) = 0.
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(4 * P + 2, N + 2 * P);
  for (int n = 0; n < P; ++n)
    for (int i = 0; i < 4; ++i) {
      A(4 * n + i, n + k[i]) = 1.0;
      A(4 * n + i, N + n) = 1.0;
      A(4 * n + i, N + P + n) = O[i];
    }
  A(4 * P, 0) = 1e4;  // the gauge rows, heavily weighted: exact constraints
  A(4 * P + 1, N - 1) = 1e4;
  const Eigen::MatrixXd Minv = (A.transpose() * A).inverse();
  const Eigen::MatrixXd G = Minv * A.topRows(4 * P).transpose();  // estimate = G · readings
  const Eigen::MatrixXd GS = G.middleRows(N, P);
  const Eigen::VectorXd sd = (sigma * sigma * GS * GS.transpose()).diagonal().cwiseSqrt();
  const double floor_dS_max = 1.87 * sd.maxCoeff();
  std::printf(
      "\nunbiased floor at sigma = 0.1 um, e known: max sd(S) = %.2f um, expected dS_max "
      "over 20 runs >= %.2f um (paper 1.1, bar 1.65)\n",
      sd.maxCoeff(), floor_dS_max);
  CHECK(floor_dS_max > 1.5 * 1.1);
}

// Does the stated uncertainty of the four-sensor separation cover the truth?  Random smooth
// profiles (core::random_smooth_truth: several harmonics of S, γ and f with random periods,
// amplitudes and phases per seed), independent noise on every sensor reading (the paper's model),
// σ = 0.05 and 0.1 µm, scans of N = 69, 300, 1000 and 5000 samples.  Per cell: the fraction of
// points with |S − S_true| <= 2·u_S (and the same for γ), and of runs whose ISO 230-1
// minimum-zone straightness lies within its U (k = 2) of the truth's, with U from the posterior
// covariance of the points that fix the zone.  Asserted: 90 % to 99 % in every cell (issue 15).
//
// Errors of S are strongly correlated along the scan (long wavelengths), so one run covers
// mostly all or mostly nothing; the cell fraction over 20 runs varies by about ±2 % (1 sd) around
// its mean for an exact covariance.  The numbers of runs are chosen for that.  The straightness
// is one figure per run: 60 runs cannot tell a U covering 95 % from one covering 100 % (60 of 60
// within U has probability 0.05 at 95 %), so N = 1000 has 100 runs.
//
// Per run (issue 15): single runs covering below 0.8 (down to 0.26 at N = 69) are the spread an
// honest u_S has when its errors are correlated along the scan, not profiles it misjudges.
// Measured with 40 (N = 69), 20 (300), 10 (1000) and 8 (5000) noise draws of each run's own
// profile: the frequentist coverage of every profile was 0.87–1.00 (mean 0.945–0.987; none below
// 0.8 of 400/200/60/80 profiles), unchanged with σ known or λ held; the lowest (0.87–0.88) are
// profiles where the prior's shrinkage bias is as large as the noise (RMS bias 0.25 vs sd 0.26 µm,
// 0.42 vs 0.48 µm at N = 69).  The count of runs below 0.8 matches what the run's own stated
// covariance predicts (errors drawn from it: 14.7 expected vs 17 seen at N = 69, σ 0.05), and is
// asserted against that prediction.
#include <Eigen/Core>
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <vector>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/four_sensor_evaluation.hpp"
#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/core/iso230.hpp"

using namespace errsep::core;

namespace {

struct Cell {
  int runs = 0;
  double cover_S = 0, cover_g = 0;  // mean over runs of the per-run fraction within 2u
  int straight_in = 0;              // runs with |T − T_true| <= U

  double rms_err = 0, med_u = 0;
  int collapses = 0;
  std::vector<double> rms, u;
  std::vector<double> per_run;  // each run's fraction of points within 2 u_S
  // Runs covering below 0.8, and what an honest u would give: each run's probability of that
  // under its own stated covariance (errors drawn from it), summed, and the variance of the count.
  int below = 0;
  double below_expected = 0, below_var = 0;
};

// The fraction of points a run covers when its error is a draw from its stated covariance: the
// spread of per-run coverage an honest u_S has at this N (errors correlated along the scan make
// it much wider than a binomial over points).  Returns the probability of covering below `floor`.
double honest_below(const FourSensorResult& r, double floor, int draws, std::uint64_t seed) {
  int n = 0;
  Eigen::VectorXd dS, dg;
  for (int d = 0; d < draws; ++d) {
    r.covariance->sample(seed + static_cast<std::uint64_t>(d), dS, dg);
    if ((dS.array().abs() <= 2.0 * r.u_S_um.array()).cast<double>().mean() < floor) ++n;
  }
  return static_cast<double>(n) / draws;
}

constexpr double per_run_floor = 0.8;
constexpr int honest_draws = 50;

Cell run_cell(int N, double sigma, int runs, FourSensorOptions opts, std::uint64_t seed0) {
  FourSensorConfig cfg;
  cfg.N = N;
  Cell cell;
  for (int k = 0; k < runs; ++k) {
    const std::uint64_t seed = seed0 + static_cast<std::uint64_t>(k);
    const SlidewayTruth truth = random_smooth_truth(cfg, seed);
    FourSensorSimOptions so;
    so.sigma_um = sigma;
    so.seed = seed * 7919 + 17;
    const FourSensorSimData sim = simulate_four_sensor(cfg, truth, so);
    FourSensorResult r = separate_four_sensor(cfg, sim.m_um, opts);
    const Eigen::VectorXd dS = r.S_um - sim.S_um, dg = r.gamma_rad - sim.gamma_rad;
    const double run_cover = (dS.array().abs() <= 2.0 * r.u_S_um.array()).cast<double>().mean();
    cell.cover_S += run_cover;
    cell.per_run.push_back(run_cover);
    if (run_cover < per_run_floor) ++cell.below;
    const double p = honest_below(r, per_run_floor, honest_draws, seed * 31 + 5);
    cell.below_expected += p;
    cell.below_var += p * (1.0 - p);
    cell.cover_g += (dg.array().abs() <= 2.0 * r.u_gamma_rad.array()).cast<double>().mean();
    cell.rms.push_back(std::sqrt(dS.squaredNorm() / static_cast<double>(dS.size())));
    cell.u.push_back(r.u_S_um.mean());
    if (r.lambda_fallback == LambdaFallback::collapse_least_squares) ++cell.collapses;
    const std::vector<double> x(r.x_mm.data(), r.x_mm.data() + r.x_mm.size());
    const std::vector<double> st(sim.S_um.data(), sim.S_um.data() + sim.S_um.size());
    const auto est = four_sensor_straightness(r, ReferenceLine::minimum_zone);
    const auto tru = evaluate_straightness(x, st, {}, ReferenceLine::minimum_zone);
    if (std::abs(est.straightness_um - tru.straightness_um) <= est.expanded_um) ++cell.straight_in;
    ++cell.runs;
  }
  cell.cover_S /= runs;
  cell.cover_g /= runs;
  auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  cell.rms_err = median(cell.rms);
  std::sort(cell.per_run.begin(), cell.per_run.end());
  cell.med_u = median(cell.u);
  return cell;
}

}  // namespace

TEST_CASE("posterior: u_S, u_gamma and the straightness U cover the truth at every scan length",
          "[sweep][four_sensor][coverage]") {
  FourSensorOptions opts;  // defaults: posterior, second-difference prior, λ by REML
  std::printf("%6s %5s %5s | %8s %8s %9s | %9s %9s %9s | %6s %6s %6s | %5s %6s %6s\n", "N", "sigma",
              "runs", "cover_S", "cover_g", "straight", "rms_err", "mean_u", "collapses", "run_mn",
              "run_10", "run_50", "<0.8", "honest", "bound");
  struct Spec {
    int N, runs;
  };
  for (const Spec spec : {Spec{69, 200}, Spec{300, 100}, Spec{1000, 100}, Spec{5000, 40}})
    for (const double sigma : {0.05, 0.1}) {
      const Cell c = run_cell(
          spec.N, sigma, spec.runs, opts,
          1000u * static_cast<std::uint64_t>(spec.N) + static_cast<std::uint64_t>(sigma * 1000));
      const double straight = static_cast<double>(c.straight_in) / c.runs;
      // Per run: no more runs below 0.8 than an honest u_S gives, by 3.5 sd of the count (a
      // sum of independent Bernoulli trials, one per run; +1 for its discreteness at small
      // expected counts).  An honest u fails this about once in 4000 cells.
      const double bound = c.below_expected + 3.5 * std::sqrt(c.below_var) + 1.0;
      const auto q = [&](double f) {
        return c.per_run[static_cast<std::size_t>(f * static_cast<double>(c.per_run.size() - 1))];
      };
      std::printf(
          "%6d %5.2f %5d | %8.3f %8.3f %9.3f | %9.3f %9.3f %9d | %6.2f %6.2f %6.2f | %5d %6.1f "
          "%6.1f\n",
          spec.N, sigma, c.runs, c.cover_S, c.cover_g, straight, c.rms_err, c.med_u, c.collapses,
          q(0.0), q(0.1), q(0.5), c.below, c.below_expected, bound);
      CHECK(static_cast<double>(c.below) <= bound);
      CHECK(c.cover_S >= 0.90);
      CHECK(c.cover_S <= 0.99);
      CHECK(c.cover_g >= 0.90);
      CHECK(c.cover_g <= 0.99);
      CHECK(straight >= 0.90);
      CHECK(straight <= 0.99);
    }
}

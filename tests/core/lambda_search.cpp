// The λ search of LambdaRule::reml (a coarse log grid, then halvings around its best point:
// four_sensor_posterior.cpp, minimise_over_lambda) against a fine grid of
// the same range (201 points, 0.05 decade apart, then 6 halvings: λ to < 0.001 decade), on random
// smooth profiles (core::random_smooth_truth) with noise on every reading.  What matters is the
// answer, not λ itself: where REML's criterion is flat λ may move without changing S.  Asserted
// per case: the same decision (regularised or collapsed to least squares) and S within 5 % of its
// median u_S of the fine search's S.
#include <Eigen/Core>
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <vector>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/four_sensor_simulation.hpp"

using namespace errsep::core;

TEST_CASE("REML lambda search: the coarse search gives the fine grid's answer", "[four_sensor]") {
  FourSensorOptions coarse;  // the defaults
  coarse.search.threads = 2;
  FourSensorOptions fine = coarse;
  fine.search.count = 201;
  int cases = 0, collapsed = 0;
  double worst_dS_over_u = 0, worst_dlog = 0;
  for (const int N : {69, 300, 1000}) {
    for (const double sigma : {0.05, 0.2}) {
      for (std::uint64_t seed = 1; seed <= 4; ++seed) {
        FourSensorConfig cfg;
        cfg.N = N;
        const SlidewayTruth truth = random_smooth_truth(cfg, 500 + seed + 10 * N);
        FourSensorSimOptions so;
        so.sigma_um = sigma;
        so.seed = seed * 7919 + static_cast<std::uint64_t>(N);
        const FourSensorSimData sim = simulate_four_sensor(cfg, truth, so);
        const FourSensorResult a = separate_four_sensor(cfg, sim.m_um, coarse);
        const FourSensorResult b = separate_four_sensor(cfg, sim.m_um, fine);
        INFO("N " << N << ", sigma " << sigma << ", seed " << seed << ": lambda " << a.lambda
                  << " vs " << b.lambda);
        ++cases;
        REQUIRE(a.lambda_fallback == b.lambda_fallback);
        if (a.lambda_fallback == LambdaFallback::collapse_least_squares) {
          ++collapsed;
          continue;
        }
        std::vector<double> u(a.u_S_um.data(), a.u_S_um.data() + a.u_S_um.size());
        std::nth_element(u.begin(), u.begin() + static_cast<long>(u.size() / 2), u.end());
        const double dS = (a.S_um - b.S_um).cwiseAbs().maxCoeff() / u[u.size() / 2];
        worst_dS_over_u = std::max(worst_dS_over_u, dS);
        worst_dlog = std::max(worst_dlog, std::abs(std::log10(a.lambda / b.lambda)));
        CHECK(dS <= 0.05);
      }
    }
  }
  std::printf(
      "lambda search vs 201-point grid: %d cases (%d collapsed in both), worst |dlog10 lambda| "
      "%.4f decade, worst max|dS|/median u_S %.4f\n",
      cases, collapsed, worst_dlog, worst_dS_over_u);
}

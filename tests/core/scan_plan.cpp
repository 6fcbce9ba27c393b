// The scan plan (core/scan_plan.hpp): the predicted uncertainty about the least-squares line and
// the straightness U against a dense computation from the full covariance written here; the
// search against a brute force over every admissible configuration; the stage's limits (range,
// step, listed positions, reference length) respected; the sampled search on a large space
// against the exhaustive one.  Whether the predicted U is met by real separations is checked by
// simulation in tests/apps/plan_app.cpp.
#include <Eigen/Dense>
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <numeric>

#include "errsep/core/four_sensor_posterior.hpp"
#include "errsep/core/scan_plan.hpp"

using namespace errsep::core;

TEST_CASE("predicted u about the line and straightness U equal the dense computation",
          "[scan_plan]") {
  for (const FourSensorConfig cfg :
       {FourSensorConfig{5.0, 1, 1, 5, 60}, FourSensorConfig{2.0, 9, 1, 10, 80}}) {
    INFO("spacings " << cfg.s2 << "," << cfg.s3 << "," << cfg.s4);
    const double sigma = 0.1, k = 2.0;
    const ScanPrediction p = predict_scan(cfg, sigma, 1, k);
    const FourSensorPrediction f = predict_four_sensor_uncertainty(cfg, sigma);
    const int P = cfg.positions();
    std::vector<int> all(static_cast<std::size_t>(P));
    std::iota(all.begin(), all.end(), 0);
    const Eigen::MatrixXd V = f.covariance->covariance_S(all);
    Eigen::MatrixXd X(P, 2);
    X.col(0).setOnes();
    X.col(1) = f.x_mm;
    const Eigen::MatrixXd R =
        Eigen::MatrixXd::Identity(P, P) - X * (X.transpose() * X).inverse() * X.transpose();
    const Eigen::MatrixXd D = R * V * R.transpose();
    const Eigen::VectorXd ud = D.diagonal().cwiseSqrt();
    CHECK((p.u_deviation_um - ud).cwiseAbs().maxCoeff() <= 1e-8 * ud.maxCoeff());
    CHECK((p.u_S_um - f.u_S_um).cwiseAbs().maxCoeff() == 0.0);
    // The mean over all pairs (a, b) of Var(δd_a − δd_b).
    double pairs = 0.0;
    for (int a = 0; a < P; ++a)
      for (int b = 0; b < P; ++b)
        pairs += D(a, a) + D(b, b) - 2.0 * D(a, b);
    pairs /= static_cast<double>(P) * P;
    CHECK(std::abs(p.u_straightness_um - std::sqrt(pairs)) <= 1e-8 * std::sqrt(pairs));
    CHECK(std::abs(p.expanded_um - k * std::sqrt(pairs)) <= 1e-8 * std::sqrt(pairs));
    CHECK(std::abs(p.expanded_bound_um - k * 2.0 * ud.maxCoeff()) <= 1e-8 * ud.maxCoeff());
    // K samples per point: every uncertainty / √K.
    const ScanPrediction p4 = predict_scan(cfg, sigma, 4, k);
    CHECK(std::abs(p4.expanded_um - 0.5 * p.expanded_um) <= 1e-9 * p.expanded_um);
    CHECK((p4.u_S_um - 0.5 * p.u_S_um).cwiseAbs().maxCoeff() <= 1e-9 * p.u_S_um.maxCoeff());
    CHECK(p4.readings() == 4LL * P * 4);
  }
  CHECK_THROWS_AS(predict_scan(FourSensorConfig{}, 0.1, 0), std::invalid_argument);
  CHECK_THROWS_AS(predict_scan(FourSensorConfig{}, 0.1, 1, 0.0), std::invalid_argument);
}

TEST_CASE("exhaustive search: the fewest readings over every admissible configuration",
          "[scan_plan]") {
  ScanPlanOptions o;
  o.travel_mm = 200.0;
  o.dx_mm = {5.0, 10.0};
  o.stage.range_mm = 50.0;
  o.sigma_um = 0.1;
  o.target_U_um = 0.6;
  const ScanPlan plan = plan_four_sensor_scan(o);
  REQUIRE(plan.exhaustive);
  // Brute force: every coprime (a, b, T) with T·dx <= 50 mm and N >= 2T + 5.
  long long count = 0, best_readings = -1;
  double best_U = 0.0;
  for (const double dx : o.dx_mm) {
    const int P = static_cast<int>(std::lround(o.travel_mm / dx)) + 1;
    for (int T = 3; T * dx <= o.stage.range_mm + 1e-9; ++T)
      for (int a = 1; a < T; ++a)
        for (int b = a + 1; b < T; ++b) {
          const FourSensorConfig c{dx, a, b - a, T - b, P + T};
          if (!c.is_valid()) continue;
          ++count;
          const double U1 = predict_scan(c, o.sigma_um).expanded_um;
          const int K = std::max(1, static_cast<int>(std::ceil(std::pow(U1 / o.target_U_um, 2))));
          if (K > o.averages_max) continue;
          const long long readings = 4LL * P * K;
          const double U = U1 / std::sqrt(K);
          if (best_readings < 0 || readings < best_readings ||
              (readings == best_readings && U < best_U))
            best_readings = readings, best_U = U;
        }
  }
  CHECK(plan.candidates == count);
  CHECK(plan.evaluated == count);
  REQUIRE(best_readings > 0);
  CHECK(plan.target_met);
  CHECK(plan.chosen.readings == best_readings);
  CHECK(std::abs(plan.chosen.expanded_um - best_U) <= 1e-9 * best_U);
  // K is the fewest that reach the target.
  const ScanPlanCandidate& c = plan.chosen;
  CHECK(c.expanded_um <= o.target_U_um);
  if (c.averages > 1) CHECK(c.expanded_one_sample_um / std::sqrt(c.averages - 1.0) > o.target_U_um);
  CHECK(std::abs(plan.prediction.expanded_um - c.expanded_um) <= 1e-9 * c.expanded_um);
  CHECK(plan.prediction.averages == c.averages);
  // The comparison: (1, 1, 5) at the same dx and K.
  CHECK(plan.baseline.config.s4 == 5);
  CHECK(plan.baseline.config.dx_mm == c.config.dx_mm);
  CHECK(plan.baseline.averages == c.averages);
  for (std::size_t i = 0; i < plan.runners_up.size(); ++i)
    CHECK(plan.runners_up[i].readings >= c.readings);
}

TEST_CASE("the stage's limits: listed positions, step, reference length", "[scan_plan]") {
  ScanPlanOptions o;
  o.travel_mm = 300.0;
  o.dx_mm = {5.0};
  o.sigma_um = 0.1;
  o.target_U_um = 0.3;
  SECTION("listed positions: every offset is one of them, from the chosen origin") {
    o.stage.positions_mm = {10.0, 15.0, 40.0, 62.5, 70.0, 105.0};
    const ScanPlan plan = plan_four_sensor_scan(o);
    const auto O = plan.chosen.config.offsets_mm();
    for (const double off : O) {
      const double pos = plan.chosen.stage_origin_mm + off;
      CHECK(std::any_of(o.stage.positions_mm.begin(), o.stage.positions_mm.end(),
                        [&](double p) { return std::abs(p - pos) < 1e-9; }));
    }
  }
  SECTION("a step that makes every offset even: refused with the reason") {
    o.stage.range_mm = 100.0;
    o.stage.step_mm = 10.0;
    CHECK_THROWS_WITH(plan_four_sensor_scan(o), Catch::Contains("no three coprime offsets"));
  }
  SECTION("a step that divides dx: the same candidates and plan as no step") {
    o.stage.range_mm = 100.0;
    o.stage.step_mm = 2.5;  // every multiple of dx is on it
    const ScanPlan any = plan_four_sensor_scan(o);
    o.stage.step_mm = 0.0;
    const ScanPlan free = plan_four_sensor_scan(o);
    CHECK(any.candidates == free.candidates);
    CHECK(any.chosen.config.s2 == free.chosen.config.s2);
    CHECK(any.chosen.config.s4 == free.chosen.config.s4);
  }
  SECTION("reference length: L + (s2 + s3 + s4)·dx within it") {
    o.stage.range_mm = 100.0;
    o.reference_length_max_mm = 340.0;
    const ScanPlan plan = plan_four_sensor_scan(o);
    CHECK(plan.chosen.config.reference_length_mm() <= 340.0 + 1e-9);
  }
}

TEST_CASE("sampled search on a large space comes within 15 % of the exhaustive optimum",
          "[scan_plan]") {
  ScanPlanOptions o;
  o.travel_mm = 1000.0;
  o.dx_mm = {5.0};
  o.stage.range_mm = 100.0;
  o.sigma_um = 0.1;
  o.target_U_um = 0.01;  // out of reach: both report their lowest U at averages_max
  o.averages_max = 1;
  const ScanPlan full = plan_four_sensor_scan(o);
  REQUIRE(full.exhaustive);
  CHECK_FALSE(full.target_met);
  o.max_evaluations = 150;
  const ScanPlan sampled = plan_four_sensor_scan(o);
  CHECK_FALSE(sampled.exhaustive);
  CHECK(sampled.evaluated <= 160);
  std::printf(
      "exhaustive: %lld predictions, U %.4f um (%d, %d, %d); sampled: %lld, U %.4f um "
      "(%d, %d, %d)\n",
      full.evaluated, full.chosen.expanded_um, full.chosen.config.s2, full.chosen.config.s3,
      full.chosen.config.s4, sampled.evaluated, sampled.chosen.expanded_um,
      sampled.chosen.config.s2, sampled.chosen.config.s3, sampled.chosen.config.s4);
  CHECK(sampled.chosen.expanded_um <= 1.15 * full.chosen.expanded_um);
}

TEST_CASE("scan plan options: each invalid field is named", "[scan_plan]") {
  std::string why;
  ScanPlanOptions o;
  CHECK(o.is_valid(&why));
  auto bad = [&](auto edit, const std::string& field) {
    ScanPlanOptions b;
    edit(b);
    std::string w;
    CHECK_FALSE(b.is_valid(&w));
    CHECK_THAT(w, Catch::Contains(field));
  };
  bad([](ScanPlanOptions& b) { b.travel_mm = -1; }, "travel_mm");
  bad([](ScanPlanOptions& b) { b.dx_mm.clear(); }, "dx_mm");
  bad([](ScanPlanOptions& b) { b.dx_mm = {0.0}; }, "dx_mm");
  bad([](ScanPlanOptions& b) { b.stage.range_mm = 0; }, "stage.range_mm");
  bad([](ScanPlanOptions& b) { b.stage.positions_mm = {0, 5, 10}; }, "stage.positions_mm");
  bad([](ScanPlanOptions& b) { b.reference_length_max_mm = 500; }, "reference_length_max_mm");
  bad([](ScanPlanOptions& b) { b.sigma_um = 0; }, "sigma_um");
  bad([](ScanPlanOptions& b) { b.averages_max = 0; }, "averages_max");
  bad([](ScanPlanOptions& b) { b.target_U_um = 0; }, "target_U_um");
  bad([](ScanPlanOptions& b) { b.max_evaluations = 1; }, "max_evaluations");
  ScanPlanOptions b;
  b.dx_mm = {7.0};  // 1000 / 7 is not whole
  CHECK_THROWS_WITH(plan_four_sensor_scan(b), Catch::Contains("not a whole number of steps"));
}

// The straightness trend over a machine's results store, on separations of simulated scans the
// test did not design for: random slideways (three harmonics of S, γ and f with random
// amplitudes and phases per seed), noise on each sensor reading (σ 0.05-0.3 µm), the daemon's
// figures (minimum zone with U, k = 2).  Counted over many machines:
//  - unchanged slideway, new noise each scan: how often a step or the drift is flagged (false
//    alarms), at most what a 5 % test allows (binomial, 1 % level);
//  - the difference of two scans' figures falls within the combined U about as the rule claims
//    (coverage of U_c for the change, >= 95 % of cases less the binomial allowance);
//  - a slideway whose S grows by a true change of more than 2 U_c between two scans: flagged
//    (counted: helps / does nothing).
// Plus the rule itself on hand-made files, the CSV and text, and a store without results.
#include "errsep/io/straightness_trend.hpp"

#include <catch2/catch.hpp>
#include <cmath>
#include <iostream>
#include <random>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/core/iso230.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/mqtt_messages.hpp"
#include "errsep/io/results_store.hpp"
#include "errsep/io/scan_report.hpp"
#include "support/refine_cases.hpp"
#include "support/result_dir.hpp"
#include "support/support.hpp"

using namespace errsep;

namespace {

constexpr double kPi = 3.14159265358979323846;

struct Harm {
  double a, period_mm, phase;
};
std::vector<Harm> random_harmonics(std::mt19937_64& rng, double amp_lo, double amp_hi,
                                   double travel_mm) {
  std::uniform_real_distribution<double> amp(amp_lo, amp_hi), ph(0, 2 * kPi);
  std::vector<Harm> h;
  for (int k = 1; k <= 3; ++k)
    h.push_back({amp(rng), travel_mm / (0.5 + k), ph(rng)});
  return h;
}
core::ProfileFn profile(std::vector<Harm> h, double scale = 1.0) {
  return [h, scale](double x) {
    double s = 0;
    for (const auto& k : h)
      s += k.a * std::sin(2 * kPi * x / k.period_mm + k.phase);
    return scale * s;
  };
}

/// Writes one scan's result file (the daemon's metadata) from a separation of simulated readings;
/// returns the true minimum-zone straightness of S on the same positions.
double store_scan(io::ResultsStore& store, std::uint64_t id, const core::SlidewayTruth& truth,
                  double sigma_um, std::uint64_t seed) {
  core::FourSensorConfig cfg;
  core::FourSensorSimOptions so;
  so.sigma_um = sigma_um;
  so.seed = seed;
  const auto sim = core::simulate_four_sensor(cfg, truth, so);
  core::FourSensorOptions fo;
  fo.compute_uncertainty = true;
  const auto r = core::separate_four_sensor(cfg, sim.m_um, fo);
  io::ScanSummary s;
  io::add_separation(s, r);
  io::CsvTable t;
  t.set_meta("scan_id", std::to_string(id));
  t.set_meta("straightness_minimum_zone_um", std::to_string(*s.straightness_minimum_zone_um));
  t.set_meta("straightness_minimum_zone_U_um", std::to_string(*s.straightness_minimum_zone_U_um));
  t.set_meta("sigma_hat_um", std::to_string(*s.sigma_hat_um));
  t.add_column("x_mm", std::vector<double>(sim.x_mm.data(), sim.x_mm.data() + sim.x_mm.size()));
  store.write(io::ResultsStore::stem(std::chrono::system_clock::now(), id), "result",
              io::format_csv(t));
  const std::vector<double> x(sim.x_mm.data(), sim.x_mm.data() + sim.x_mm.size());
  const std::vector<double> S(sim.S_um.data(), sim.S_um.data() + sim.S_um.size());
  return core::evaluate_straightness(x, S, {}, core::ReferenceLine::minimum_zone).straightness_um;
}

io::ResultsStore make_store(const std::filesystem::path& dir) {
  io::ResultsStoreOptions o;
  o.dir = dir;
  o.min_free_bytes = 0;
  return io::ResultsStore(o);
}

}  // namespace

TEST_CASE(
    "trend on random slideways: false alarms, coverage of the combined U, real changes found") {
  constexpr int kMachines = 24, kScans = 5;
  int steps = 0, false_steps = 0, drifts = 0, false_drifts = 0, covered = 0, changes = 0;
  int helped = 0, missed = 0, big_changes = 0;
  double mean_Uc = 0;
  for (int m = 0; m < kMachines; ++m) {
    std::mt19937_64 rng(1000 + static_cast<std::uint64_t>(m));
    const double travel = 69 * 5.0;
    std::uniform_real_distribution<double> sig(0.05, 0.3), e(-5, 5);
    const double sigma = sig(rng);
    core::SlidewayTruth truth;
    const auto hS = random_harmonics(rng, 0.5, 3.0, travel);
    truth.S_um = profile(hS);
    truth.gamma_rad = profile(random_harmonics(rng, 1e-6, 5e-6, travel));
    truth.f_um = profile(random_harmonics(rng, 0.2, 1.0, travel));
    truth.e_um = {0, e(rng), e(rng), e(rng)};
    test::TempDir tmp;
    auto store = make_store(tmp / "results");
    std::vector<double> true_t;
    for (int k = 0; k < kScans; ++k)
      true_t.push_back(store_scan(store, static_cast<std::uint64_t>(k + 1), truth, sigma,
                                  static_cast<std::uint64_t>(m * 100 + k)));
    const auto tr = io::straightness_trend(tmp / "results");
    REQUIRE(tr.points.size() == kScans);
    for (std::size_t k = 1; k < tr.points.size(); ++k) {
      ++steps;
      false_steps += tr.points[k].significant ? 1 : 0;
      ++changes;
      // The true change is 0 here: the measured change lies within U_c?
      covered +=
          std::abs(tr.points[k].change_um - (true_t[k] - true_t[k - 1])) <= tr.points[k].change_U_um
              ? 1
              : 0;
      mean_Uc += tr.points[k].change_U_um;
    }
    ++drifts;
    false_drifts += tr.points.back().drift_significant ? 1 : 0;

    // The slideway wears: S grows; a sixth scan with the worn S.
    const double grow =
        1.0 + 4.0 * tr.points.back().change_U_um / std::max(1e-9, tr.points.back().straightness_um);
    core::SlidewayTruth worn = truth;
    worn.S_um = profile(hS, grow);
    const double t6 = store_scan(store, kScans + 1, worn, sigma, m * 100 + 99);
    const auto tr2 = io::straightness_trend(tmp / "results");
    REQUIRE(tr2.points.size() == kScans + 1);
    const auto& last = tr2.points.back();
    if (t6 - true_t.back() > 2 * last.change_U_um) {
      ++big_changes;
      (last.significant ? helped : missed) += 1;
    }
  }
  mean_Uc /= steps;
  std::cout << "trend: " << kMachines << " random slideways x " << kScans
            << " scans, sigma 0.05-0.3 um: false step flags " << false_steps << "/" << steps
            << ", false drift flags " << false_drifts << "/" << drifts << ", change within U_c "
            << covered << "/" << changes << " (mean U_c " << mean_Uc
            << " um); true change > 2 U_c flagged " << helped << "/" << big_changes << "\n";
  CHECK(false_steps <= test::allowed_beyond_2u(static_cast<std::size_t>(steps)));
  CHECK(false_drifts <= test::allowed_beyond_2u(static_cast<std::size_t>(drifts)));
  CHECK(changes - covered <= test::allowed_beyond_2u(static_cast<std::size_t>(changes)));
  REQUIRE(big_changes >= kMachines / 2);
  CHECK(missed <= big_changes / 10);
}

TEST_CASE("trend rule on hand-made results: step, drift, skipped files, CSV and text") {
  test::TempDir tmp;
  auto store = make_store(tmp / "results");
  auto put = [&](std::uint64_t id, const char* t_um, const char* U_um) {
    io::CsvTable t;
    if (t_um) t.set_meta("straightness_minimum_zone_um", t_um);
    if (U_um) t.set_meta("straightness_minimum_zone_U_um", U_um);
    t.add_column("x_mm", {0, 1});
    store.write(io::ResultsStore::stem(std::chrono::system_clock::now(), id), "result",
                io::format_csv(t));
  };
  put(1, "3.0", "0.4");
  put(2, "3.5", "0.4");      // change 0.5 < sqrt(0.32) = 0.566: not significant
  put(3, "3.9", "0.3");      // change 0.4 < 0.5; drift 0.9 > 0.5: significant
  put(4, nullptr, nullptr);  // a result without figures (separation failed): skipped
  put(10, "2.0", "0.3");     // change -1.9: significant (ids sort numerically: 10 after 4)
  const auto t = io::straightness_trend(tmp / "results");
  REQUIRE(t.points.size() == 4);
  CHECK(t.skipped.size() == 1);
  CHECK_FALSE(t.points[1].significant);
  CHECK(t.points[1].change_U_um == Approx(std::sqrt(0.32)));
  CHECK_FALSE(t.points[2].significant);
  CHECK(t.points[2].drift_significant);
  CHECK(t.points[3].scan_number == 10);
  CHECK(t.points[3].significant);
  CHECK(t.any_significant());
  const auto c = io::trend_table(t);
  CHECK(c.columns.front() == "scan_number");
  CHECK(c.column("significant") == std::vector<double>{0, 0, 0, 1});
  const std::string text = io::format_trend(t);
  CHECK(text.find("SIGNIFICANT") != std::string::npos);
  CHECK(text.find("skipped") != std::string::npos);
  CHECK_THROWS_WITH(io::straightness_trend(tmp / "nope"), Catch::Contains("not a directory"));
}

TEST_CASE("the report shows the trend of the results store and warns of a significant change") {
  test::TempDir tmp;
  test::write_four_sensor_result(tmp / "report");
  auto store = make_store(tmp / "results");
  const std::vector<std::pair<const char*, const char*>> figures = {
      {"3.0", "0.4"}, {"3.2", "0.4"}, {"4.5", "0.4"}};
  std::uint64_t id = 0;
  for (const auto& [t_um, U_um] : figures) {
    io::CsvTable t;
    t.set_meta("straightness_minimum_zone_um", t_um);
    t.set_meta("straightness_minimum_zone_U_um", U_um);
    t.add_column("x_mm", {0, 1});
    store.write(io::ResultsStore::stem(std::chrono::system_clock::now(), ++id), "result",
                io::format_csv(t));
  }
  io::ScanReportOptions o;
  o.plots = false;
  o.tables = false;
  o.trend_results_dir = tmp / "results";
  const auto res = io::write_scan_report(tmp / "report", o);
  CHECK(std::filesystem::exists(tmp / "report" / "trend.csv"));
  CHECK(res.text.find("Straightness trend") != std::string::npos);
  CHECK(res.text.find("SIGNIFICANT") != std::string::npos);
  bool warned = false;
  for (const auto& w : res.warnings)
    warned = warned || w.find("changed beyond the combined U") != std::string::npos;
  CHECK(warned);
  const auto t = io::read_csv(tmp / "report" / "trend.csv");
  CHECK(t.column("significant") == std::vector<double>{0, 0, 1});
  // Without the option: no trend.
  o.trend_results_dir.clear();
  const auto plain = io::write_scan_report(tmp / "report", o);
  CHECK(plain.text.find("Straightness trend") == std::string::npos);
}

// Issue 21: a reading no sensor can give (-8.7e10 um, which made errsep-refine fail inside Boost's
// F distribution with no file or line), inf, nan, a position out of order and a time going
// backwards are each refused with "file:line:" and exit status 1 by every app that reads raw
// scans -- errsep-separate, errsep-refine, errsep-report (on a result folder holding the raw
// scan) and errsep-separate-displacement -- before any computation, and nothing is written.
#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>
#include <tuple>

#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "support/support.hpp"

using namespace errsep;
namespace fs = std::filesystem;

namespace {

io::RawFourSensorScan simulated_raw() {
  const core::FourSensorConfig cfg;
  core::FourSensorSimOptions so;
  so.sigma_um = 0.1;
  so.seed = 21;
  const auto sim = core::simulate_four_sensor(cfg, core::zhao2019_example1(cfg), so);
  io::RawFourSensorScan raw;
  raw.complete = true;
  raw.geometry = cfg;
  raw.x_mm.assign(sim.x_mm.data(), sim.x_mm.data() + sim.x_mm.size());
  raw.t_s.emplace();
  for (std::size_t j = 0; j < 4; ++j)
    for (Eigen::Index n = 0; n < sim.m_um.rows(); ++n) {
      raw.m_um[j].push_back(sim.m_um(n, static_cast<Eigen::Index>(j)));
      (*raw.t_s)[j].push_back(100.0 * static_cast<double>(j) + 0.5 * static_cast<double>(n));
    }
  for (int i = 1; i <= 4; ++i) {
    const std::string m = "m" + std::to_string(i);
    raw.metadata.emplace_back("range_min_" + m + "_um", "-2000");
    raw.metadata.emplace_back("range_max_" + m + "_um", "2000");
  }
  return raw;
}

struct Bad {
  std::string name, what;
  std::size_t row;
  std::function<void(io::RawFourSensorScan&)> spoil;
};

}  // namespace

TEST_CASE("impossible values in a raw scan: every app refuses them with file:line") {
  const std::vector<Bad> cases = {
      {"a reading of -8.7e10 um", "outside the sensor's range -2000 to 2000 um", 17,
       [](io::RawFourSensorScan& r) { r.m_um[1][17] = -8.7e10; }},
      {"inf", "not a finite reading", 5,
       [](io::RawFourSensorScan& r) { r.m_um[3][5] = std::numeric_limits<double>::infinity(); }},
      {"nan in a complete scan", "not measured", 30,
       [](io::RawFourSensorScan& r) { r.m_um[0][30] = std::nan(""); }},
      {"a position out of order", "positions must increase", 9,
       [](io::RawFourSensorScan& r) { r.x_mm[9] = r.x_mm[7]; }},
      {"a time going backwards", "time goes backwards", 40,
       [](io::RawFourSensorScan& r) { (*r.t_s)[2][40] = (*r.t_s)[2][39] - 1.0; }},
  };
  for (const auto& c : cases) {
    DYNAMIC_SECTION(c.name) {
      test::TempDir tmp;
      io::RawFourSensorScan raw = simulated_raw();
      c.spoil(raw);
      fs::create_directories(tmp / "set");
      const fs::path file = tmp / "set" / "raw.csv";
      io::write_raw_four_sensor_csv(file, raw);
      const std::string where =
          file.string() + ":" + std::to_string(errsep::test::data_line(file, c.row)) + ":";
      const std::vector<std::pair<std::string, std::string>> runs = {
          {"errsep-separate", test::app_path("separate").string() + " " + file.string() +
                                  " --out " + (tmp / "sep").string()},
          {"errsep-refine", test::app_path("refine").string() + " " + file.string() + " --out " +
                                (tmp / "ref").string()},
          {"errsep-report",
           test::app_path("report").string() + " " + (tmp / "set").string() + " --no-plots"},
      };
      for (const auto& [app, cmd] : runs) {
        std::string out;
        const int rc = test::run_command(cmd, &out);
        INFO(app << ": " << out);
        CHECK(rc == 1);
        CHECK_THAT(out, Catch::Contains(where) && Catch::Contains(c.what));
        CHECK_THAT(out, !Catch::Contains("boost::math"));
      }
      CHECK_FALSE(fs::exists(tmp / "sep"));
      CHECK_FALSE(fs::exists(tmp / "ref"));
      CHECK_FALSE(fs::exists(tmp / "set" / "report.html"));
    }
  }
}

TEST_CASE("impossible values in displacement scans: errsep-separate-displacement refuses them") {
  test::TempDir tmp;
  // A raw displacement scan (ranges recorded), and the hand-made layouts (the default bound).
  io::RawDisplacementScan s;
  for (int n = 0; n < 8; ++n) {
    s.x_mm.push_back(5.0 * n);
    s.s1_scan1_um.push_back(0.3 * n);
    s.s2_scan1_um.push_back(0.2 * n - 1);
    s.s1_scan2_um.push_back(0.3 * n + 0.01);
    s.s2_scan2_um.push_back(0.2 * n - 0.8);
  }
  s.d_mm = 5;
  s.complete = true;
  s.metadata = {{"range_min_s1_um", "-100"},
                {"range_max_s1_um", "100"},
                {"range_min_s2_um", "-100"},
                {"range_max_s2_um", "100"}};
  s.s2_scan1_um[3] = -8.7e10;
  const fs::path raw = tmp / "raw_displacement.csv";
  io::write_raw_displacement_csv(raw, s);
  const std::string three = (tmp / "three.csv").string();
  std::ofstream(three) << "x_mm,m1_um,m2_um,m3_um\n0,0.1,0.2,0.3\n5,0.2,0.1,0\n10,-8.7e10,0.3,0.1\n"
                          "15,0,0.2,0.2\n";
  const std::vector<std::tuple<std::string, std::string, std::string>> runs = {
      {"one-axis -i " + raw.string(),
       raw.string() + ":" + std::to_string(errsep::test::data_line(raw, 3)) + ":",
       "outside the sensor's range -100 to 100 um"},
      {"three-point -i " + three, three + ":4:", "beyond any displacement sensor"},
  };
  for (const auto& [args, where, what] : runs) {
    std::string out;
    const int rc = test::run_command(test::app_path("separate-displacement").string() + " " + args +
                                         " -o " + (tmp / "out.csv").string(),
                                     &out);
    INFO(args << ": " << out);
    CHECK(rc == 1);
    CHECK_THAT(out, Catch::Contains(where) && Catch::Contains(what));
    CHECK_FALSE(fs::exists(tmp / "out.csv"));
  }
}

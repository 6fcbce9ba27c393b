// errsep-simulate run as a user would: the truth it writes is the truth errsep-refine --truth
// reads (io::read_truth_csv, the reader behind --truth), and the sensor positioning error PE1
// (Zhao 2019 section 3) is a miss of +12, -15, +20 um on whatever spacings the geometry has, not
// the paper's 5.012, 4.985, 25.02 mm laid on another Δx.
#include <catch2/catch.hpp>
#include <cmath>
#include <regex>

#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "errsep/io/reference_csv.hpp"
#include "support/support.hpp"

using namespace errsep;
using test::TempDir;

namespace {

int simulate(const std::string& args, std::string* out) {
  return test::run_command(test::app_path("simulate").string() + " " + args + " 2>&1", out);
}

/// "truth comparison: max|dS| = X um" of the app's output; NaN when absent.
double max_dS_um(const std::string& out) {
  std::smatch m;
  static const std::regex re(R"(max\|dS\| = ([-+0-9.eE]+) um)");
  return std::regex_search(out, m, re) ? std::stod(m[1]) : std::nan("");
}

}  // namespace

TEST_CASE("errsep-simulate writes a truth CSV that errsep-refine --truth reads") {
  TempDir tmp;
  std::string out;
  REQUIRE(simulate("--out " + (tmp / "sim").string() + " --dx-mm 4 --N 60 --seed 5", &out) == 0);
  INFO(out);
  const auto raw = io::read_raw_four_sensor_csv(tmp / "sim" / "raw.csv");
  REQUIRE(raw.geometry);
  const core::FourSensorConfig cfg = *raw.geometry;
  CHECK(cfg.dx_mm == 4.0);
  const auto truth = io::read_truth_csv(tmp / "sim" / "truth.csv", cfg, raw.x_mm.front());
  REQUIRE(truth.f_um.size() == cfg.N);
  REQUIRE(truth.S_um.size() == cfg.positions());
  // The values are the paper's Example 1 (Eqs. 21-23) on this grid, not another profile.
  const auto t = core::zhao2019_example1(cfg);
  for (Eigen::Index n = 0; n < cfg.positions(); ++n) {
    const double x = raw.x_mm[static_cast<std::size_t>(n)];
    CHECK(truth.S_um(n) == Approx(t.S_um(x)).margin(1e-9));
    CHECK(truth.gamma_rad(n) == Approx(t.gamma_rad(x)).margin(1e-12));
  }
  for (Eigen::Index j = 0; j < cfg.N; ++j)
    CHECK(truth.f_um(j) == Approx(t.f_um(j * cfg.dx_mm)).margin(1e-9));

  // And errsep-refine takes it as it is written.
  std::string refine_out;
  CHECK(test::run_command(test::app_path("refine").string() + " " +
                              (tmp / "sim" / "raw.csv").string() + " --truth " +
                              (tmp / "sim" / "truth.csv").string() + " --out " +
                              (tmp / "refined").string() + " 2>&1",
                          &refine_out) == 0);
  INFO(refine_out);
  CHECK_THAT(test::read_file(tmp / "refined" / "refine_report.txt"),
             Catch::Contains("error vs truth"));
}

TEST_CASE("PE1 is a miss on the geometry's own spacings, at any dx") {
  // The paper's geometry gives the paper's figures.
  const auto paper = core::zhao2019_pe1_spacing_mm();
  CHECK(paper[0] == Approx(5.012));
  CHECK(paper[1] == Approx(4.985));
  CHECK(paper[2] == Approx(25.02));
  core::FourSensorConfig g;
  g.dx_mm = 2.0;
  g.s4 = 7;
  const auto d = core::zhao2019_pe1_spacing_mm(g);
  CHECK(d[0] == Approx(2.012));
  CHECK(d[1] == Approx(1.985));
  CHECK(d[2] == Approx(14.02));

  // End to end without noise: the separation's error stays at the scale of the misses (the
  // paper's 0.1 um at dx = 5 mm), not the tens of um of 5 mm spacings laid on a 2 mm grid.
  TempDir tmp;
  std::string out;
  REQUIRE(simulate("--out " + (tmp / "pe1").string() + " --dx-mm 2 --N 120 --pe1 --sigma-um 0",
                   &out) == 0);
  INFO(out);
  const double err = max_dS_um(out);
  CHECK(err < 1.0);
}

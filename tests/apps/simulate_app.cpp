// errsep-simulate run as a user would: the truth it writes is the truth errsep-refine --truth
// reads (io::read_truth_csv, the reader behind --truth), and the sensor positioning error PE1
// (Zhao 2019 section 3) is a miss of +12, -15, +20 um on whatever spacings the geometry has, not
// the paper's 5.012, 4.985, 25.02 mm laid on another Δx.
#include <catch2/catch.hpp>
#include <cmath>
#include <regex>

#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "errsep/io/reference_csv.hpp"
#include "support/result_files.hpp"
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

TEST_CASE(
    "errsep-simulate --method displacement writes the raw file errsep-scan writes, separated as "
    "errsep-separate-displacement separates it, and its truth") {
  TempDir tmp;
  const auto dir = tmp / "sim";
  std::string out;
  // Sensor 1 drifts (0.02 um/s over a ~52 s scan pair), scan 2 backwards, the loop on.
  const int rc = simulate("--method displacement --out " + dir.string() +
                              " --sigma-um 0.1 --seed 3 --scan2-order backward "
                              "--drift-um-per-s 0.02 0 --refine",
                          &out);
  INFO(out);
  REQUIRE(rc == 0);
  CHECK_THAT(out, Catch::Contains("truth comparison (separation)"));
  for (const char* f :
       {"raw_displacement.csv", "truth.csv", "displacement.csv", "displacement_residuals.csv",
        "refine/displacement_refine.csv", "refine/displacement.csv"}) {
    INFO(f);
    CHECK(std::filesystem::exists(dir / f));
  }
  // The raw file as errsep-scan's: the order of scan 2 and its times round-trip.
  const auto raw = io::read_raw_displacement_csv(dir / "raw_displacement.csv");
  CHECK(raw.complete);
  CHECK(raw.scan2_order == core::DisplacementScanOrder::backward);
  REQUIRE(raw.t_scan2_s);
  CHECK(raw.t_scan2_s->front() > raw.t_scan2_s->back());
  CHECK(raw.t_scan1_s->front() < raw.t_scan1_s->back());

  // The same result as errsep-separate-displacement gives on the raw file.
  std::string sep_out;
  REQUIRE(test::run_command(test::app_path("separate-displacement").string() + " one-axis -i " +
                                (dir / "raw_displacement.csv").string() + " -o " +
                                (tmp / "sep.csv").string() + " 2>&1",
                            &sep_out) == 0);
  const auto a = io::read_csv(dir / "displacement.csv"), b = io::read_csv(tmp / "sep.csv");
  for (const char* c : {"w_um", "m_um", "u_w_um"}) {
    const auto ca = a.column(c), cb = b.column(c);
    REQUIRE(ca.size() == cb.size());
    for (std::size_t k = 0; k < ca.size(); ++k)
      CHECK(ca[k] == Approx(cb[k]).margin(1e-9));
  }

  // The loop names the drift of sensor 1 (identifiable with scan 2 backwards) and estimates its
  // rate within 4 u of the injected one.
  const auto t =
      io::read_csv(dir / "refine" / "displacement_refine.csv", {.allow_non_finite = true});
  CHECK(t.meta("step1_effect") == std::optional<std::string>("drift of sensor 1"));
  CHECK(t.meta("step1_decision") != std::optional<std::string>("not identifiable"));
  const auto v = t.column("value"), u = t.column("u");
  REQUIRE(!v.empty());
  CHECK(std::abs(v[0] - 0.02) <= 4 * u[0]);

  // The truth is Haramiishi 2024 Fig. 5's inputs.  With scan 2 backwards sensor 1's linear drift
  // leaves w's shape alone (the mean time of a point's two readings is the same everywhere): the
  // separation's w lies within 4 u(w) of the truth; the refined u is never below it.
  const auto truth = io::read_csv(dir / "truth.csv");
  const auto wt = truth.column("w_um");
  const auto ws = a.column("w_um"), us = a.column("u_w_um");
  const auto ur = io::read_csv(dir / "refine" / "displacement.csv").column("u_w_um");
  REQUIRE(wt.size() == ws.size());
  REQUIRE(ur.size() == us.size());
  double mean = 0;
  for (std::size_t k = 0; k < wt.size(); ++k)
    mean += (ws[k] - wt[k]) / static_cast<double>(wt.size());
  for (std::size_t k = 0; k < wt.size(); ++k) {
    CHECK(std::abs(ws[k] - wt[k] - mean) <= 4 * us[k]);
    CHECK(ur[k] >= us[k] * (1 - 1e-12));
  }
  std::printf("simulate displacement, backward, sensor 1 drift 0.02 um/s: w error %.4f um rms\n",
              test::rms_shape(ws, wt));
}

TEST_CASE(
    "errsep-simulate --method displacement refuses four drift values and --refine without it") {
  TempDir tmp;
  std::string out;
  CHECK(simulate(
            "--method displacement --out " + (tmp / "a").string() + " --drift-um-per-s 0.1 0 0 0",
            &out) != 0);
  CHECK_THAT(out, Catch::Contains("take 2 values with --method displacement"));
  CHECK(simulate("--out " + (tmp / "b").string() + " --refine", &out) != 0);
  CHECK_THAT(out, Catch::Contains("for --method displacement"));
}

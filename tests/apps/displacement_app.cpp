// errsep-separate-displacement and errsep-budget run as a user would: on good CSVs (results
// checked against the simulated truth) and on bad ones (clear error, non-zero exit, nothing
// written, an existing result left alone).
#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <sstream>

#include "errsep/core/displacement_simulation.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "support/support.hpp"

using namespace errsep;
using test::TempDir;

namespace {

std::string app() {
  return test::app_path("separate-displacement").string();
}

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::vector<double> vec(const Eigen::VectorXd& v) {
  return {v.data(), v.data() + v.size()};
}

void write_one_axis(const std::filesystem::path& p, const core::OneAxisSimData& s) {
  io::CsvTable t;
  t.add_column("x_mm", vec(s.x_mm));
  t.add_column("s1_scan1_um", vec(s.s1_1_um));
  t.add_column("s2_scan1_um", vec(s.s2_1_um));
  t.add_column("s2_scan2_um", vec(s.s2_2_um));
  io::write_csv(p, t);
}

/// Two-axis grid in long format, rows in reverse raster order (the reader must not care);
/// `skip` drops one row, `drop_column` leaves one sensor column out.
void write_two_axis(const std::filesystem::path& p, const core::TwoAxisScan& s, int skip = -1,
                    const std::string& drop_column = "") {
  const Eigen::Index nx = s.x_mm.size(), ny = s.y_mm.size();
  const std::pair<const char*, const Eigen::MatrixXd*> m[] = {
      {"s0_scan1_um", &s.s0_1_um}, {"s1_scan1_um", &s.s1_1_um}, {"s1_scan2_um", &s.s1_2_um},
      {"s2_scan1_um", &s.s2_1_um}, {"s2_scan2_um", &s.s2_2_um}, {"s3_scan1_um", &s.s3_1_um},
      {"s3_scan2_um", &s.s3_2_um}, {"s4_scan1_um", &s.s4_1_um}, {"s4_scan2_um", &s.s4_2_um}};
  std::vector<std::vector<double>> cols(11);
  int row = 0;
  for (Eigen::Index j = ny - 1; j >= 0; --j)
    for (Eigen::Index i = nx - 1; i >= 0; --i, ++row) {
      if (row == skip) continue;
      cols[0].push_back(s.x_mm(i));
      cols[1].push_back(s.y_mm(j));
      for (int c = 0; c < 9; ++c)
        cols[2 + c].push_back((*m[c].second)(i, j));
    }
  io::CsvTable t;
  t.add_column("x_mm", cols[0]);
  t.add_column("y_mm", cols[1]);
  for (int c = 0; c < 9; ++c)
    if (drop_column != m[c].first) t.add_column(m[c].first, cols[2 + c]);
  io::write_csv(p, t);
}

int run(const std::string& args, std::string* out) {
  return test::run_command(app() + " " + args, out);
}

}  // namespace

TEST_CASE("one-axis: the app recovers r, m, w from a simulated scan") {
  TempDir dir;
  const auto sim = core::simulate_one_axis(core::haramiishi2024_fig5_truth(), {});
  write_one_axis(dir / "scan.csv", sim);
  std::string out;
  const int rc =
      run("one-axis -i " + (dir / "scan.csv").string() + " -o " + (dir / "res.csv").string(), &out);
  INFO(out);
  REQUIRE(rc == 0);
  const auto t = io::read_csv(dir / "res.csv");
  REQUIRE(t.columns == std::vector<std::string>{"x_mm", "r_um", "m_um", "w_um"});
  const auto w = t.column("w_um"), m = t.column("m_um");
  for (std::size_t k = 0; k < w.size(); ++k) {
    CHECK(w[k] == Approx(sim.w_um(static_cast<Eigen::Index>(k))).margin(1e-6));
    CHECK(m[k] == Approx(sim.m_um(static_cast<Eigen::Index>(k))).margin(1e-6));
  }
}

TEST_CASE("one-axis: the app reads a raw displacement scan as errsep-scan records it (d = 2 dx)") {
  TempDir dir;
  core::OneAxisTruth truth = core::haramiishi2024_fig5_truth();
  core::OneAxisSimOptions so;
  so.displacement_mm = 10.0;
  const auto sim = core::simulate_one_axis(truth, so);
  io::RawDisplacementScan raw;
  raw.x_mm = vec(sim.x_mm);
  raw.s1_scan1_um = vec(sim.s1_1_um);
  raw.s2_scan1_um = vec(sim.s2_1_um);
  raw.s1_scan2_um = vec(sim.s1_1_um);
  raw.s2_scan2_um = vec(sim.s2_2_um);
  raw.d_mm = 10.0;
  raw.complete = true;
  io::write_raw_displacement_csv(dir / "raw.csv", raw);
  std::string out;
  REQUIRE(run("one-axis -i " + (dir / "raw.csv").string() + " -o " + (dir / "res.csv").string(),
              &out) == 0);
  CHECK_THAT(out, Catch::Contains("d/dx = 2"));
  const auto t = io::read_csv(dir / "res.csv");
  CHECK(t.meta("step_ratio").value() == "2");
  const auto w = t.column("w_um");
  for (std::size_t k = 0; k < w.size(); ++k)  // r linear: least roughness joins the chains exactly
    CHECK(w[k] == Approx(sim.w_um(static_cast<Eigen::Index>(k))).margin(1e-6));
  // --d-mm contradicting the recorded d is an error, not a silent override
  CHECK(
      run("one-axis --d-mm 5 -i " + (dir / "raw.csv").string() + " -o " + (dir / "r2.csv").string(),
          &out) == 1);
  CHECK_THAT(out, Catch::Contains("contradicts the file's d_mm"));
  CHECK_FALSE(std::filesystem::exists(dir / "r2.csv"));
  // an incomplete (aborted) scan is refused
  raw.complete = false;
  io::write_raw_displacement_csv(dir / "part.csv", raw);
  CHECK(run("one-axis -i " + (dir / "part.csv").string() + " -o " + (dir / "r3.csv").string(),
            &out) == 1);
  CHECK_THAT(out, Catch::Contains("incomplete"));
  CHECK_FALSE(std::filesystem::exists(dir / "r3.csv"));
}

TEST_CASE("two-axis: the app recovers w(x, y) on a grid, with and without rotation correction") {
  TempDir dir;
  core::TwoAxisSimOptions so;
  so.nx = 9;
  so.ny = 7;
  const auto sim = core::simulate_two_axis(core::example_two_axis_truth(), so);
  write_two_axis(dir / "grid.csv", sim.scan);
  std::string out;
  REQUIRE(run("two-axis -i " + (dir / "grid.csv").string() + " -o " + (dir / "w.csv").string(),
              &out) == 0);
  const auto t = io::read_csv(dir / "w.csv");
  REQUIRE(t.rows.size() == 63);
  const auto x = t.column("x_mm"), y = t.column("y_mm"), w = t.column("w_um");
  std::vector<double> err;
  for (std::size_t r = 0; r < w.size(); ++r) {
    const auto i = static_cast<Eigen::Index>(std::lround(x[r] / 5.0));
    const auto j = static_cast<Eigen::Index>(std::lround(y[r] / 5.0));
    err.push_back(w[r] - sim.w_um(i, j));
  }
  for (double e : err)
    CHECK(e == Approx(err[0]).margin(1e-6));  // w up to a constant
  REQUIRE(run("two-axis --no-rotation-correction -i " + (dir / "grid.csv").string() + " -o " +
                  (dir / "w0.csv").string(),
              &out) == 0);
  CHECK(io::read_csv(dir / "w0.csv").meta("rotation_correction").value() == "off");
}

TEST_CASE("three-point: the app writes profile and motion") {
  TempDir dir;
  core::SlidewayProfiles s{[](double x) { return std::sin(x / 20.0); },
                           [](double x) { return 0.1 * x; }, [](double) { return 2e-6; }};
  const Eigen::MatrixXd m = core::simulate_three_sensor(s, {});
  io::CsvTable t;
  std::vector<double> x;
  for (int n = 0; n < m.rows(); ++n)
    x.push_back(5.0 * n);
  t.add_column("x_mm", x);
  t.add_column("m1_um", vec(m.col(0)));
  t.add_column("m2_um", vec(m.col(1)));
  t.add_column("m3_um", vec(m.col(2)));
  io::write_csv(dir / "tp.csv", t);
  std::string out;
  REQUIRE(run("three-point -i " + (dir / "tp.csv").string() + " -o " + (dir / "f.csv").string() +
                  " --motion-out " + (dir / "mo.csv").string(),
              &out) == 0);
  CHECK(io::read_csv(dir / "f.csv").rows.size() == 25);
  const auto g = io::read_csv(dir / "mo.csv").column("gamma_urad");
  CHECK(g.size() == 23);
}

TEST_CASE("bad input: clear error, non-zero exit, nothing written") {
  TempDir dir;
  const auto res = dir / "res.csv";
  std::string out;
  auto expect_fail = [&](const std::string& args, const std::vector<std::string>& needles) {
    const int rc = run(args + " -o " + res.string(), &out);
    INFO(args << "\n" << out);
    CHECK(rc == 1);
    for (const auto& n : needles)
      CHECK_THAT(out, Catch::Contains(n));
    CHECK_FALSE(std::filesystem::exists(res));
  };

  // one axis: d that does not match the sampling
  const auto sim = core::simulate_one_axis(core::haramiishi2024_fig5_truth(), {});
  write_one_axis(dir / "scan.csv", sim);
  expect_fail("one-axis --d-mm 7.5 -i " + (dir / "scan.csv").string(),
              {"scan.csv", "not an integer multiple", "7.5"});
  // non-finite number
  std::ofstream(dir / "nan.csv")
      << "x_mm,s1_scan1_um,s2_scan1_um,s2_scan2_um\n0,1,2,3\n5,1,nan,3\n10,1,2,3\n";
  expect_fail("one-axis -i " + (dir / "nan.csv").string(), {"nan.csv:3", "non-finite"});
  // missing sensor column
  std::ofstream(dir / "miss.csv") << "x_mm,s1_scan1_um,s2_scan1_um\n0,1,2\n5,1,2\n";
  expect_fail("one-axis -i " + (dir / "miss.csv").string(),
              {"miss.csv", "missing column 's2_scan2_um'"});
  // non-uniform sampling
  std::ofstream(dir / "gap.csv")
      << "x_mm,s1_scan1_um,s2_scan1_um,s2_scan2_um\n0,1,2,3\n5,1,2,3\n15,1,2,3\n";
  expect_fail("one-axis -i " + (dir / "gap.csv").string(), {"gap.csv:4", "sampling interval"});

  // two axes: ragged grid, duplicate point, missing sensor column
  core::TwoAxisSimOptions so;
  so.nx = 4;
  so.ny = 3;
  const auto grid = core::simulate_two_axis(core::example_two_axis_truth(), so);
  write_two_axis(dir / "ragged.csv", grid.scan, 5);
  expect_fail(
      "two-axis -i " + (dir / "ragged.csv").string(),
      {"ragged.csv", "ragged grid", "need 12 points", "has 11", "missing (x_mm = 10, y_mm = 5)"});
  write_two_axis(dir / "nos3.csv", grid.scan, -1, "s3_scan2_um");
  expect_fail("two-axis -i " + (dir / "nos3.csv").string(), {"missing column 's3_scan2_um'"});
  {
    std::string text = slurp(dir / "ragged.csv");
    const auto last = text.rfind('\n', text.size() - 2);
    text += text.substr(last + 1);  // repeat the last row
    std::ofstream(dir / "dup.csv") << text;
  }
  expect_fail("two-axis -i " + (dir / "dup.csv").string(), {"dup.csv:13", "appears again"});
  write_two_axis(dir / "grid.csv", grid.scan);
  expect_fail("two-axis --d-y-mm 12 -i " + (dir / "grid.csv").string(),
              {"y axis", "not an integer multiple"});
  // three-point without enough columns
  expect_fail("three-point -i " + (dir / "scan.csv").string(), {"missing column 'm1_um'"});
  // missing input file
  expect_fail("one-axis -i " + (dir / "none.csv").string(), {"none.csv", "cannot open"});

  // a failing run leaves an existing result untouched
  std::ofstream(res) << "previous result\n";
  CHECK(run("one-axis --d-mm 7.5 -i " + (dir / "scan.csv").string() + " -o " + res.string(),
            &out) == 1);
  CHECK(slurp(res) == "previous result\n");
}

TEST_CASE("errsep-budget prints and writes the paper budget, and fails cleanly on a bad config") {
  TempDir dir;
  const std::string budget = test::app_path("budget").string();
  const std::string cfg = (test::source_dir() / "config" / "budget-haramiishi2024.toml").string();
  std::string out;
  REQUIRE(test::run_command(budget + " -c " + cfg + " --csv " + (dir / "b.csv").string() +
                                " --text " + (dir / "b.txt").string(),
                            &out) == 0);
  CHECK_THAT(out, Catch::Contains("sigma_w^2 = 68.2472 um^2, sigma_w = 8.2612 um"));
  CHECK_THAT(out, Catch::Contains("sigma_tt = 1.0556 um"));
  CHECK(io::read_csv(dir / "b.csv").rows.size() == 6);
  CHECK(slurp(dir / "b.txt") == out);
  std::ofstream(dir / "bad.toml") << "[temperature]\nchange_K = \"four\"\n";
  CHECK(test::run_command(
            budget + " -c " + (dir / "bad.toml").string() + " --csv " + (dir / "c.csv").string(),
            &out) == 1);
  CHECK_THAT(out, Catch::Contains("bad.toml:2: temperature.change_K: expected a number"));
  CHECK_FALSE(std::filesystem::exists(dir / "c.csv"));
}

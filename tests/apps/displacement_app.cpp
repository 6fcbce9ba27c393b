// errsep-separate-displacement and errsep-budget run as a user would: on good CSVs (results
// checked against the simulated truth) and on bad ones (clear error, non-zero exit, nothing
// written, an existing result left alone).
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>

#include "errsep/core/displacement_simulation.hpp"
#include "errsep/core/two_axis_yaw.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "support/displacement_cases.hpp"
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

/// A 13 x 11 grid at the paper's noise (σ_se 0.16 µm, σ_sc 0.29 µm), sensor 0 read in both scans.
core::TwoAxisSimOptions noisy_grid(std::uint64_t seed) {
  core::TwoAxisSimOptions so;
  so.nx = 13;
  so.ny = 11;
  so.eddy_sensor.noise_sigma_um = 0.16;
  so.contact_sensor.noise_sigma_um = 0.29;
  so.record_s0_scan2 = true;
  so.seed = seed;
  return so;
}

/// Two-axis grid in long format, rows in reverse raster order (the reader must not care);
/// `skip` drops one row, `drop_column` leaves one sensor column out; s0_scan2_um is written when
/// the scan has it, the lateral pair's four columns when given.
void write_two_axis(const std::filesystem::path& p, const core::TwoAxisScan& s, int skip = -1,
                    const std::string& drop_column = "",
                    const core::LateralPairScan* lateral = nullptr,
                    const Eigen::MatrixXd* t_scan1_s = nullptr) {
  const Eigen::Index nx = s.x_mm.size(), ny = s.y_mm.size();
  std::vector<std::pair<const char*, const Eigen::MatrixXd*>> m = {
      {"s0_scan1_um", &s.s0_1_um}, {"s1_scan1_um", &s.s1_1_um}, {"s1_scan2_um", &s.s1_2_um},
      {"s2_scan1_um", &s.s2_1_um}, {"s2_scan2_um", &s.s2_2_um}, {"s3_scan1_um", &s.s3_1_um},
      {"s3_scan2_um", &s.s3_2_um}, {"s4_scan1_um", &s.s4_1_um}, {"s4_scan2_um", &s.s4_2_um}};
  if (s.s0_2_um.size()) m.push_back({"s0_scan2_um", &s.s0_2_um});
  if (lateral) {
    m.push_back({"sa_scan1_um", &lateral->ua_1_um});
    m.push_back({"sa_scan2_um", &lateral->ua_2_um});
    m.push_back({"sb_scan1_um", &lateral->ub_1_um});
    m.push_back({"sb_scan2_um", &lateral->ub_2_um});
  }
  if (t_scan1_s) m.push_back({"t_scan1_s", t_scan1_s});
  std::vector<std::vector<double>> cols(2 + m.size());
  int row = 0;
  for (Eigen::Index j = ny - 1; j >= 0; --j)
    for (Eigen::Index i = nx - 1; i >= 0; --i, ++row) {
      if (row == skip) continue;
      cols[0].push_back(s.x_mm(i));
      cols[1].push_back(s.y_mm(j));
      for (std::size_t c = 0; c < m.size(); ++c)
        cols[2 + c].push_back((*m[c].second)(i, j));
    }
  io::CsvTable t;
  t.add_column("x_mm", cols[0]);
  t.add_column("y_mm", cols[1]);
  for (std::size_t c = 0; c < m.size(); ++c)
    if (drop_column != m[c].first) t.add_column(m[c].first, cols[2 + c]);
  io::write_csv(p, t);
}

/// The metadata value `key` of a CSV file ("" when absent).
std::string meta_of(const std::filesystem::path& p, const std::string& key) {
  return io::read_csv(p).meta(key).value_or("");
}

/// Leading number of a metadata value such as "0.1603 (per reading, ...)".
double leading_number(const std::string& v) {
  return std::stod(v);
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

TEST_CASE("two-axis: per-point u columns, the rotation decision and the row-by-row solver") {
  TempDir dir;
  const auto so = noisy_grid(12);
  const auto truth = test::random_two_axis_truth(12, 60.0);
  const auto sim = core::simulate_two_axis(truth, so);
  write_two_axis(dir / "grid.csv", sim.scan);
  std::string out;
  REQUIRE(run("two-axis --rotation-correction on -i " + (dir / "grid.csv").string() + " -o " +
                  (dir / "w.csv").string(),
              &out) == 0);
  CHECK(out.find("gauge:") != std::string::npos);
  const auto t = io::read_csv(dir / "w.csv");
  CHECK(t.meta("rotation_correction").value() == "on");
  CHECK(t.meta("solver").value() == "joint");
  CHECK(t.meta("gauge").value().find("r1_x") != std::string::npos);
  CHECK(t.meta("sigma_workpiece_um").value().find("sensor 0 repeat") != std::string::npos);
  CHECK(t.meta("rotation_decision").value().find("predicted") != std::string::npos);
  const auto gt = test::gauged_truth(truth, sim, so.geometry, true);
  const auto x = t.column("x_mm"), y = t.column("y_mm"), w = t.column("w_um"),
             u = t.column("u_w_um"), m2 = t.column("m2x_um"), um2 = t.column("u_m2x_um");
  for (const char* c : {"u_m_w_um", "u_m1x_um", "u_m3y_um", "u_m4y_um", "u_m_wxe_um", "u_m_wye_um",
                        "u_r1x_um", "u_r2x_um", "u_r3y_um", "u_r4y_um"})
    CHECK(t.find_column(c));
  double worst_z = 0;
  for (std::size_t r = 0; r < w.size(); ++r) {
    const auto i = static_cast<Eigen::Index>(std::lround(x[r] / 5.0));
    const auto j = static_cast<Eigen::Index>(std::lround(y[r] / 5.0));
    REQUIRE(u[r] > 0);
    REQUIRE(um2[r] > 0);
    worst_z = std::max(
        {worst_z, std::abs(w[r] - gt.w(i, j)) / u[r], std::abs(m2[r] - gt.m[1](i, j)) / um2[r]});
  }
  INFO("worst |error| / u over " << w.size() << " points: " << worst_z);
  CHECK(worst_z < 5.0);
  // The paper's path for comparison: no uncertainty columns; auto means on there.
  REQUIRE(run("two-axis --solver row-by-row -i " + (dir / "grid.csv").string() + " -o " +
                  (dir / "wr.csv").string(),
              &out) == 0);
  const auto tr = io::read_csv(dir / "wr.csv");
  CHECK(tr.meta("solver").value() == "row-by-row");
  CHECK_FALSE(tr.find_column("u_w_um"));
  // Default auto: the decision and both predictions in the metadata.
  REQUIRE(run("two-axis -i " + (dir / "grid.csv").string() + " -o " + (dir / "wa.csv").string(),
              &out) == 0);
  CHECK(io::read_csv(dir / "wa.csv").meta("rotation_decision").value().find("(auto)") !=
        std::string::npos);
  CHECK(run("two-axis --rotation-correction sideways -i " + (dir / "grid.csv").string() + " -o " +
                (dir / "wx.csv").string(),
            &out) != 0);
}

TEST_CASE("one-axis: u columns when sigma is known, none (and said why) when it is not") {
  TempDir dir;
  core::OneAxisSimOptions so;
  so.workpiece_sensor.noise_sigma_um = so.reference_sensor.noise_sigma_um = 0.1;
  so.seed = 3;
  const auto sim = core::simulate_one_axis(core::haramiishi2024_fig5_truth(), so);
  write_one_axis(dir / "scan.csv", sim);
  std::string out;
  REQUIRE(run("one-axis -i " + (dir / "scan.csv").string() + " -o " + (dir / "a.csv").string(),
              &out) == 0);
  CHECK(out.find("no uncertainty") != std::string::npos);
  CHECK_FALSE(io::read_csv(dir / "a.csv").find_column("u_w_um"));
  REQUIRE(run("one-axis --reading-sigma-um 0.1 -i " + (dir / "scan.csv").string() + " -o " +
                  (dir / "b.csv").string(),
              &out) == 0);
  const auto t = io::read_csv(dir / "b.csv");
  const auto u = t.column("u_w_um"), ur = t.column("u_r_um");
  REQUIRE(u.size() == 25);
  // Eq. (9): r's error at x_k has sd σ√(2k); w adds m's and sensor 1's own reading.
  CHECK(ur[24] == Approx(0.1 * std::sqrt(48.0)).epsilon(1e-9));
  CHECK(u[0] == Approx(0.1 * std::sqrt(2.0)).epsilon(1e-9));
  CHECK(t.meta("sigma_source").value() == "given");
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

TEST_CASE("one-axis: the residuals are written beside the result, with sigma_hat and whiteness") {
  TempDir dir;
  core::OneAxisSimOptions so;
  so.workpiece_sensor.noise_sigma_um = 0.29;
  so.reference_sensor.noise_sigma_um = 0.16;
  so.seed = 11;
  const auto sim = core::simulate_one_axis(core::haramiishi2024_fig5_truth(), so);
  // A raw scan as errsep-scan records it: s1 is read in both scans.
  io::RawDisplacementScan raw;
  raw.x_mm = vec(sim.x_mm);
  raw.s1_scan1_um = vec(sim.s1_1_um);
  raw.s2_scan1_um = vec(sim.s2_1_um);
  raw.s1_scan2_um = vec(sim.s1_2_um);
  raw.s2_scan2_um = vec(sim.s2_2_um);
  raw.d_mm = 5.0;
  raw.complete = true;
  io::write_raw_displacement_csv(dir / "raw.csv", raw);
  std::string out;
  const int rc =
      run("one-axis -i " + (dir / "raw.csv").string() + " -o " + (dir / "res.csv").string(), &out);
  INFO(out);
  REQUIRE(rc == 0);
  CHECK_THAT(out, Catch::Contains("workpiece_repeat: 25 equations, dof 24"));
  const auto rpath = dir / "res.residuals.csv";
  REQUIRE(std::filesystem::exists(rpath));
  const auto t = io::read_csv(rpath);
  CHECK(t.columns == std::vector<std::string>{"family", "sensor", "scan", "run", "order", "x_mm",
                                              "value_um", "residual_um"});
  REQUIRE(t.rows.size() == 25);
  // value = S1_2 - S1_1; residual = value minus its mean
  const auto v = t.column("value_um"), e = t.column("residual_um");
  double mean = 0;
  for (std::size_t k = 0; k < 25; ++k) {
    CHECK(v[k] == Approx(sim.s1_2_um(static_cast<Eigen::Index>(k)) -
                         sim.s1_1_um(static_cast<Eigen::Index>(k)))
                      .margin(1e-8));
    mean += v[k] / 25.0;
  }
  for (std::size_t k = 0; k < 25; ++k)
    CHECK(e[k] == Approx(v[k] - mean).margin(1e-8));
  const double sigma = leading_number(t.meta("family_1_sigma_um").value());
  std::printf("one-axis app: family_1_sigma_um: %s\n  whiteness: %s\n",
              t.meta("family_1_sigma_um").value().c_str(),
              t.meta("family_1_whiteness").value_or("").c_str());
  CHECK(sigma > 0.29 * 0.55);  // χ²_24 99.9 % interval of σ̂/σ: 0.55-1.50
  CHECK(sigma < 0.29 * 1.50);
  CHECK_THAT(t.meta("family_1_whiteness").value_or(""), Catch::Contains("p = "));
  CHECK_THAT(t.meta("family_1_offset_um").value_or(""), Catch::Contains("+-"));
  CHECK_THAT(meta_of(dir / "res.csv", "residual_verdict"), Catch::Contains("workpiece_repeat"));
  CHECK(meta_of(dir / "res.csv", "residuals") == rpath.string());

  // Eqs. (1)-(3) only: the residual file says there is nothing to test.
  write_one_axis(dir / "plain.csv", sim);
  REQUIRE(run("one-axis -i " + (dir / "plain.csv").string() + " -o " + (dir / "p.csv").string() +
                  " --residuals-out " + (dir / "pres.csv").string(),
              &out) == 0);
  const auto pt = io::read_csv(dir / "pres.csv", io::CsvReadOptions{false, 0});
  CHECK(pt.rows.empty());
  CHECK(pt.meta("verdict").value() == "nothing to test");
  CHECK_THAT(pt.meta("note").value_or(""), Catch::Contains("exactly determined"));

  // The table moving during scan 2 (4 um thermal rise, tau 8 samples, both sensors; the size
  // tests/core/displacement_residuals.cpp finds in 40 of 40 seeds): reported as not white, exit
  // status still 0 (a diagnosis, not an input error).
  for (std::size_t k = 0; k < raw.x_mm.size(); ++k) {
    const double h = 4.0 * (1.0 - std::exp(-static_cast<double>(k) / 8.0));
    raw.s1_scan2_um[k] += h;
    raw.s2_scan2_um[k] += h;
  }
  io::write_raw_displacement_csv(dir / "moved.csv", raw);
  REQUIRE(run("one-axis -i " + (dir / "moved.csv").string() + " -o " + (dir / "m.csv").string(),
              &out) == 0);
  CHECK_THAT(out, Catch::Contains("NOT white"));
  CHECK_THAT(meta_of(dir / "m.csv", "residual_verdict"), Catch::StartsWith("NOT white"));
  CHECK_THAT(meta_of(dir / "m.residuals.csv", "verdict"), Catch::StartsWith("not white"));

  // Repeated runs: -i twice; the runs' own family appears, the result is the mean's.
  so.seed = 12;
  const auto sim2 = core::simulate_one_axis(core::haramiishi2024_fig5_truth(), so);
  raw.s1_scan1_um = vec(sim2.s1_1_um);
  raw.s2_scan1_um = vec(sim2.s2_1_um);
  raw.s1_scan2_um = vec(sim2.s1_2_um);
  raw.s2_scan2_um = vec(sim2.s2_2_um);
  io::write_raw_displacement_csv(dir / "raw2.csv", raw);
  REQUIRE(run("one-axis -i " + (dir / "raw.csv").string() + " -i " + (dir / "raw2.csv").string() +
                  " -o " + (dir / "r2.csv").string(),
              &out) == 0);
  CHECK_THAT(out, Catch::Contains("repeated_runs: 200 equations, dof 100"));
  CHECK(meta_of(dir / "r2.csv", "runs") == "2 (mean)");
}

TEST_CASE("two-axis: residuals of the reference pieces and sensor 0, a thermal drift reported") {
  TempDir dir;
  auto so = noisy_grid(5);
  const auto sim = core::simulate_two_axis(core::example_two_axis_truth(), so);
  write_two_axis(dir / "grid.csv", sim.scan);
  std::string out;
  REQUIRE(run("two-axis -i " + (dir / "grid.csv").string() + " -o " + (dir / "w.csv").string(),
              &out) == 0);
  INFO(out);
  const auto t = io::read_csv(dir / "w.residuals.csv");
  CHECK(t.columns == std::vector<std::string>{"family", "sensor", "scan", "run", "order", "x_mm",
                                              "y_mm", "value_um", "residual_um"});
  CHECK(t.rows.size() == 5 * 143);  // four reference sensors + sensor 0, one row per point
  // dof: 2·13·10 + 2·11·12 = 524 for the reference pieces, 142 for sensor 0.
  CHECK_THAT(t.meta("family_1_dof").value(), Catch::StartsWith("524"));
  CHECK_THAT(t.meta("family_2_dof").value(), Catch::StartsWith("142"));
  const double se = leading_number(t.meta("family_1_sigma_um").value());
  const double sc = leading_number(t.meta("family_2_sigma_um").value());
  std::printf(
      "two-axis app: sigma_hat eddy %.4f um (truth 0.16, dof 524), contact %.4f um (truth "
      "0.29, dof 142)\n",
      se, sc);
  CHECK(se > 0.16 * 0.90);  // χ²_524 99.9 % interval: 0.90-1.10
  CHECK(se < 0.16 * 1.10);
  CHECK(sc > 0.29 * 0.80);  // χ²_142 99.9 % interval: 0.80-1.20
  CHECK(sc < 0.29 * 1.20);
  // Residual of sensor 1 at one point = D1 minus its mean over the rows (y).
  {
    const auto fam = t.column("family"), sen = t.column("sensor"), x = t.column("x_mm"),
               y = t.column("y_mm"), e = t.column("residual_um");
    const Eigen::Index i = 4, j = 7;
    double mean = 0;
    for (Eigen::Index jj = 0; jj < 11; ++jj)
      mean += (sim.scan.s1_2_um(i, jj) - sim.scan.s1_1_um(i, jj)) / 11.0;
    const double expect = sim.scan.s1_2_um(i, j) - sim.scan.s1_1_um(i, j) - mean;
    int hits = 0;
    for (std::size_t r = 0; r < e.size(); ++r)
      if (fam[r] == 1 && sen[r] == 1 && x[r] == 20.0 && y[r] == 35.0) {
        ++hits;
        CHECK(e[r] == Approx(expect).margin(1e-8));
      }
    CHECK(hits == 1);
  }

  // The eddy-current sensors drift thermally on the paper's 25 x 25 grid (0.5 um, tau 600 s,
  // 1 s per point: the size of the paper's Fig. 14, which tests/core/displacement_residuals.cpp
  // finds in 5 of 5 seeds): not white.
  so.nx = 25;
  so.ny = 25;
  core::TwoAxisScan drift = core::simulate_two_axis(core::example_two_axis_truth(), so).scan;
  for (int j = 0; j < 25; ++j)
    for (int i = 0; i < 25; ++i) {
      const double t1 = j * 25 + i, t2 = 625 + t1;
      for (auto* m : {&drift.s1_1_um, &drift.s2_1_um, &drift.s3_1_um, &drift.s4_1_um})
        (*m)(i, j) += 0.5 * (1 - std::exp(-t1 / 600.0));
      for (auto* m : {&drift.s1_2_um, &drift.s2_2_um, &drift.s3_2_um, &drift.s4_2_um})
        (*m)(i, j) += 0.5 * (1 - std::exp(-t2 / 600.0));
    }
  write_two_axis(dir / "drift.csv", drift);
  REQUIRE(run("two-axis -i " + (dir / "drift.csv").string() + " -o " + (dir / "wd.csv").string(),
              &out) == 0);
  CHECK_THAT(out, Catch::Contains("NOT white"));
  CHECK_THAT(meta_of(dir / "wd.residuals.csv", "family_1_whiteness"),
             Catch::StartsWith("not white"));
}

namespace {

// Yaw ψ(x, y) = Σ c_kl P_k(u) P_l(v) (µrad, order (0,0), (0,1), (1,0), (1,1), (2,0), (2,1)) on
// the 120 mm grid, a side face and a lateral straightness for the lateral pair.
core::YawTruth yaw_truth(const Eigen::VectorXd& c_urad) {
  core::YawTruth y;
  y.yaw_rad = [c_urad](double x, double yy) {
    const double u = x / 60.0 - 1.0, v = yy / 60.0 - 1.0;
    const double P[3] = {1.0, u, 1.5 * u * u - 0.5}, Q[2] = {1.0, v};
    double s = 0;
    int k = 0;
    for (int a = 0; a <= 2; ++a)
      for (int b = 0; b <= 1; ++b)
        s += c_urad(k++) * P[a] * Q[b];
    return 1e-6 * s;
  };
  y.side_um = [](double xi) { return 2.0 * std::sin(2.0 * 3.141592653589793 * xi / 150.0); };
  y.offset_a_um = 12.3;
  y.offset_b_um = -40.0;
  y.lateral_um = [](double x, double yy) {
    return 3.0 * std::sin(2.0 * 3.141592653589793 * x / 80.0) + 0.02 * yy;
  };
  return y;
}

// w's error at each point of a w column (column major, nx x ny) against the truth, its mean
// removed (a constant of w is not determined).
std::vector<double> shape_error(const std::vector<double>& w, const Eigen::MatrixXd& truth) {
  std::vector<double> e(w.size());
  double mean = 0;
  for (std::size_t k = 0; k < w.size(); ++k) {
    e[k] = w[k] - truth(static_cast<Eigen::Index>(k) % truth.rows(),
                        static_cast<Eigen::Index>(k) / truth.rows());
    mean += e[k] / static_cast<double>(w.size());
  }
  for (auto& v : e)
    v -= mean;
  return e;
}

double rms(const std::vector<double>& e) {
  double s = 0;
  for (const double v : e)
    s += v * v / static_cast<double>(e.size());
  return std::sqrt(s);
}

}  // namespace

TEST_CASE("two-axis: the lateral pair columns switch on the yaw diagnosis, a yaw is found") {
  // An inclined workpiece (10 and 5 um/mm: yaw acts on heights through slopes) on the example
  // stage, the yaw of a poor stage (up to ~0.5 mrad), low noise so that the yaw's share of the w
  // error stands above the floor (as tests/core/refine_effects_more.cpp).
  TempDir dir;
  core::TwoAxisTruth truth = core::example_two_axis_truth();
  const core::GridFn w0 = truth.w_um;
  truth.w_um = [w0](double x, double y) { return w0(x, y) + 10.0 * x + 5.0 * y; };
  core::TwoAxisSimOptions so;
  so.eddy_sensor.noise_sigma_um = 0.002;
  so.contact_sensor.noise_sigma_um = 0.002;
  so.seed = 41;
  const core::YawGeometry geo;  // lateral sensors at 0 and 100 mm, axis at s = 0, x = 60 mm
  Eigen::VectorXd c(6);
  c << 150.0, 60.0, 250.0, 0.0, -80.0, 40.0;
  const auto with = core::simulate_two_axis_yaw(truth, yaw_truth(c), so, geo);
  const auto without =
      core::simulate_two_axis_yaw(truth, yaw_truth(Eigen::VectorXd::Zero(6)), so, geo);
  write_two_axis(dir / "yaw.csv", with.two_axis.scan, -1, "", &with.lateral);
  write_two_axis(dir / "clean.csv", without.two_axis.scan, -1, "", &without.lateral);
  std::string out;
  REQUIRE(run("two-axis -i " + (dir / "yaw.csv").string() + " -o " + (dir / "wy.csv").string(),
              &out) == 0);
  INFO(out);
  const auto t = io::read_csv(dir / "wy.csv");
  std::printf("yaw app: %s\n", t.meta("yaw").value_or("(none)").c_str());
  CHECK_THAT(t.meta("yaw").value_or(""), Catch::StartsWith("significant"));
  REQUIRE(t.find_column("yaw_urad"));
  REQUIRE(t.find_column("w_before_yaw_um"));
  // w corrected: closer to the truth than before the correction (errors without their mean).
  const auto x = t.column("x_mm"), y = t.column("y_mm"), w = t.column("w_um"),
             wb = t.column("w_before_yaw_um"), psi = t.column("yaw_urad");
  std::vector<double> ea, eb;
  double psi_err = 0, psi_rms = 0;
  for (std::size_t r = 0; r < w.size(); ++r) {
    const auto i = static_cast<Eigen::Index>(std::lround(x[r] / 5.0));
    const auto j = static_cast<Eigen::Index>(std::lround(y[r] / 5.0));
    ea.push_back(w[r] - with.two_axis.w_um(i, j));
    eb.push_back(wb[r] - with.two_axis.w_um(i, j));
    psi_err += std::pow(psi[r] - 1e6 * (with.yaw_rad(i, j) - 1e-6 * c(0)), 2);
    psi_rms += std::pow(1e6 * (with.yaw_rad(i, j) - 1e-6 * c(0)), 2);
  }
  auto centred_rms = [](std::vector<double> e) {
    double m = 0;
    for (double v : e)
      m += v / static_cast<double>(e.size());
    double s = 0;
    for (double v : e)
      s += (v - m) * (v - m);
    return std::sqrt(s / static_cast<double>(e.size()));
  };
  const double after = centred_rms(ea), before = centred_rms(eb);
  std::printf(
      "yaw app: w error rms %.4f -> %.4f um; yaw (less its constant) rms %.1f urad, error "
      "rms %.2f urad\n",
      before, after, std::sqrt(psi_rms / static_cast<double>(w.size())),
      std::sqrt(psi_err / static_cast<double>(w.size())));
  CHECK(after < 0.5 * before);
  CHECK(std::sqrt(psi_err / psi_rms) < 0.1);

  // The same stage without yaw: diagnosed, nothing corrected.
  REQUIRE(run("two-axis -i " + (dir / "clean.csv").string() + " -o " + (dir / "wc.csv").string(),
              &out) == 0);
  const auto tc = io::read_csv(dir / "wc.csv");
  std::printf("yaw app, clean: %s\n", tc.meta("yaw").value_or("(none)").c_str());
  CHECK_THAT(tc.meta("yaw").value_or(""), Catch::StartsWith("not significant"));
  const auto wc = tc.column("w_um"), wcb = tc.column("w_before_yaw_um");
  CHECK(wc == wcb);
  // --no-yaw skips it; --yaw without the columns is an input error.
  REQUIRE(
      run("two-axis --no-yaw -i " + (dir / "yaw.csv").string() + " -o " + (dir / "wn.csv").string(),
          &out) == 0);
  CHECK_FALSE(io::read_csv(dir / "wn.csv").meta("yaw").has_value());
  write_two_axis(dir / "nolat.csv", with.two_axis.scan);
  CHECK(
      run("two-axis --yaw -i " + (dir / "nolat.csv").string() + " -o " + (dir / "wx.csv").string(),
          &out) == 1);
  CHECK_THAT(out, Catch::Contains("--yaw needs the lateral pair columns"));
  CHECK_FALSE(std::filesystem::exists(dir / "wx.csv"));
  CHECK_FALSE(std::filesystem::exists(dir / "wx.residuals.csv"));
}

TEST_CASE(
    "residual inputs: bad optional columns and mismatched runs are refused, nothing written") {
  TempDir dir;
  const auto res = dir / "res.csv";
  const auto resid = dir / "res.residuals.csv";
  std::string out;
  auto expect_fail = [&](const std::string& args, const std::vector<std::string>& needles) {
    const int rc = run(args + " -o " + res.string(), &out);
    INFO(args << "\n" << out);
    CHECK(rc == 1);
    for (const auto& n : needles)
      CHECK_THAT(out, Catch::Contains(n));
    CHECK_FALSE(std::filesystem::exists(res));
    CHECK_FALSE(std::filesystem::exists(resid));
  };
  // one axis: a nan in the optional workpiece column of scan 2 names its line
  std::ofstream(dir / "nan2.csv") << "x_mm,s1_scan1_um,s2_scan1_um,s2_scan2_um,s1_scan2_um\n"
                                     "0,1,2,3,1\n5,1,2,3,1\n10,1,2,3,nan\n";
  expect_fail("one-axis -i " + (dir / "nan2.csv").string(), {"nan2.csv:4", "non-finite"});
  // repeated runs on different grids
  const auto sim = core::simulate_one_axis(core::haramiishi2024_fig5_truth(), {});
  write_one_axis(dir / "a.csv", sim);
  std::ofstream(dir / "b.csv") << "x_mm,s1_scan1_um,s2_scan1_um,s2_scan2_um\n0,1,2,3\n5,1,2,3\n";
  expect_fail("one-axis -i " + (dir / "a.csv").string() + " -i " + (dir / "b.csv").string(),
              {"b.csv", "x positions differ"});
  // two axes: only some of the lateral pair's columns; a nan in s0_scan2_um
  core::TwoAxisSimOptions so;
  so.nx = 4;
  so.ny = 3;
  so.record_s0_scan2 = true;
  const auto grid = core::simulate_two_axis(core::example_two_axis_truth(), so);
  core::LateralPairScan lat{grid.scan.s1_1_um, grid.scan.s1_2_um, grid.scan.s2_1_um,
                            grid.scan.s2_2_um};
  write_two_axis(dir / "part.csv", grid.scan, -1, "sb_scan2_um", &lat);
  expect_fail("two-axis -i " + (dir / "part.csv").string(),
              {"part.csv", "missing column 'sb_scan2_um'", "lateral sensor pair"});
  write_two_axis(dir / "g.csv", grid.scan);
  {
    // the last field of the last row (line 13: header + 12 points) is s0_scan2_um: make it nan
    const std::string text = slurp(dir / "g.csv");
    std::ofstream(dir / "g0.csv") << text.substr(0, text.rfind(',') + 1) << "nan\n";
  }
  expect_fail("two-axis -i " + (dir / "g0.csv").string(), {"g0.csv:13", "non-finite"});
  so.nx = 5;
  const auto other = core::simulate_two_axis(core::example_two_axis_truth(), so);
  write_two_axis(dir / "o.csv", other.scan);
  expect_fail("two-axis -i " + (dir / "g.csv").string() + " -i " + (dir / "o.csv").string(),
              {"o.csv", "grid differs"});
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

// Issue 16 item 4: the two-axis loop (core/displacement_refine.hpp) in the app.  A linear drift
// of every sensor on a grid scanned with scan 2 y fastest and backwards (the plan the library
// says identifies it) is taken and the refined w lies within 4 u of the truth; scanned in the
// paper's order the account says the drift is not identifiable from this plan.
TEST_CASE("two-axis --refine: a sensor drift is taken on the plan that identifies it") {
  TempDir dir;
  auto run_plan = [&](bool backward_y_fastest, const std::string& name, double drift = 1.0,
                      std::uint64_t seed = 21) {
    core::TwoAxisSimOptions so;
    so.nx = 15;
    so.ny = 15;
    so.eddy_sensor.noise_sigma_um = 0.1;
    so.contact_sensor.noise_sigma_um = 0.18;
    so.record_s0_scan2 = true;
    so.seed = seed;
    so.timing.sample_period_s = 1.0;
    so.timing.pause_between_scans_s = 60.0;
    so.reverse_scan2 = backward_y_fastest;
    so.y_fastest_scan2 = backward_y_fastest;
    // About 0.005 σ per s on each sensor: core/displacement_refine's drift cells (0.002 σ per s on
    // 25 x 25) scaled to this shorter scan.
    // Seed 21 keeps the signs it always had; other seeds draw a random sign per sensor.
    so.disturbance.drift_um_per_s = {0.0004, -0.0006, 0.0005, 0.00045, -0.00055};
    std::mt19937_64 rng(seed);
    for (auto& v : so.disturbance.drift_um_per_s)
      v *= drift * (seed == 21 || rng() % 2 ? 1.0 : -1.0);
    const auto sim = core::simulate_two_axis(test::random_two_axis_truth(seed, 0.0), so);
    write_two_axis(dir / (name + ".csv"), sim.scan);
    std::string out;
    const std::string plan = backward_y_fastest ? " --scan2-order backward --scan2-y-fastest" : "";
    const int rc =
        run("two-axis --refine --no-yaw --pause-s 60" + plan + " -i " +
                (dir / (name + ".csv")).string() + " -o " + (dir / (name + "_w.csv")).string(),
            &out);
    INFO(out);
    REQUIRE(rc == 0);
    CHECK_THAT(out, Catch::Contains("displacement refine"));
    return sim;
  };

  // Five seeds (random stage, noise and drift signs; ~0.4 s each).
  int halved = 0;
  for (std::uint64_t seed = 21; seed <= 25; ++seed) {
    const std::string name = "bw" + std::to_string(seed);
    const auto sim = run_plan(true, name, 1.0, seed);
    const auto t =
        io::read_csv(dir / (name + "_w.refine.csv"), {.allow_non_finite = true, .min_rows = 0});
    CHECK(t.meta("plan").value_or("") != "");
    bool drift_taken = false;
    for (int s = 1; s <= std::stoi(t.meta("steps").value_or("0")); ++s)
      drift_taken =
          drift_taken ||
          t.meta("step" + std::to_string(s) + "_effect").value_or("").rfind("drift", 0) == 0;
    CHECK(drift_taken);
    const auto before = shape_error(io::read_csv(dir / (name + "_w.csv")).column("w_um"), sim.w_um);
    const auto refined = io::read_csv(dir / (name + "_w.refined.csv"));
    const auto after = shape_error(refined.column("w_um"), sim.w_um);
    const auto u = refined.column("u_w_um");
    // The same grid and noise without the drift, for scale (printed).
    const auto clean_sim = run_plan(true, "clean" + std::to_string(seed), 0.0, seed);
    int within = 0;
    for (std::size_t k = 0; k < after.size(); ++k)
      within += std::abs(after[k]) <= 4 * u[k];
    std::printf(
        "two-axis, seed %llu, drift on every sensor, scan 2 y fastest backwards: w error %.3f -> "
        "%.3f um rms (applied: %s; without the drift %.3f); within 4u at %d/%zu points\n",
        static_cast<unsigned long long>(seed), rms(before), rms(after),
        t.meta("applied_any").value_or("?").c_str(),
        rms(shape_error(
            io::read_csv(dir / ("clean" + std::to_string(seed) + "_w.csv")).column("w_um"),
            clean_sim.w_um)),
        within, after.size());
    halved += rms(after) <= 0.5 * rms(before);
    CHECK(within == static_cast<int>(after.size()));
  }
  // Halved in >= 80 % of the runs (issue 16).  Rotation on auto: before the refine re-took the
  // decision (core/displacement_refine.hpp) the drift switched the correction on and the refined
  // w errors were 0.85/1.66/1.27/1.09/2.34 um (seed 22 not halved), now 0.20/0.38/0.26/0.33/0.21.
  std::printf("  halved in %d/5 seeds\n", halved);
  CHECK(halved >= 4);

  (void)run_plan(false, "paper");
  // Nothing may be taken there: the account may have no rows.
  const auto tp =
      io::read_csv(dir / "paper_w.refine.csv", {.allow_non_finite = true, .min_rows = 0});
  bool said = false;
  for (int i = 1; tp.meta("note" + std::to_string(i)); ++i) {
    const auto n = *tp.meta("note" + std::to_string(i));
    said = said || (n.find("drift") != std::string::npos && n.find("not") != std::string::npos);
  }
  CHECK(said);
}

// Issue 16 item 2 in the app: scan 1 along wrapped diagonals (--scan1-diagonal), the plan the
// effect library names for a thermal drift of sensors 3-4.  Per seed a random stage (several
// harmonics, random phases and amplitudes), independent noise on every reading (sigma 0.1 um,
// sensor 0 at 1.8 sigma), a thermal drift on sensors 3-4 only (random size 1.5-3 sigma and sign
// per sensor, tau 0.3-3 scans), 20 x 20 grid, scan 1 diagonal and scan 2 y fastest backwards,
// with t_scan1_s recorded.  Declared with the flag: the account carries no "poorly determined"
// line for sensors 3-4 and the refined w is not worse than the separation's beyond 2 u(w) (the
// refined u, and the tighter u of the separation before the refine); the same file declared
// without the flag is refused, naming the file, the declared plan and what its times show.
// The stage has no roll or pitch (rotation_urad 0) and the correction of Eqs. (22)-(27) is on
// auto: the separation's decision sees the noise, not the drift, and switches it on in 16 of these
// runs (w error before the refine median 3.4 um RMS, 0.48 with it off); the refine re-takes it
// with the drift its redundancy sees (core/displacement_refine.hpp) and leaves it off in 19
// (measured: refined w error median 0.20 um RMS; before that change, with auto, seed 1615 ended
// at 4.24 um against a stated u(w) of 1.27 um RMS; now 0.38 against 0.24).  Seed 1607 stays on
// (τ poorly determined: 2.39 um against u 3.85).
// ~9 s CPU in release (21 refines of 400 points; about 70 % of each run is the residuals'
// Monte-Carlo whiteness test), [sweep]: not run under ASan.
TEST_CASE("two-axis --refine --scan1-diagonal: a thermal drift of sensors 3-4 on its plan",
          "[refine][sweep]") {
  TempDir dir;
  constexpr int kN = 20;
  constexpr double kSigma = 0.1;
  core::TwoAxisScanOrder order;
  order.sample_period_s = 1.0;
  order.pause_between_scans_s = 60.0;
  order.reverse_scan2 = true;
  order.y_fastest_scan2 = true;
  order.diagonal_scan1 = true;
  Eigen::MatrixXd t1(kN, kN);
  for (int j = 0; j < kN; ++j)
    for (int i = 0; i < kN; ++i)
      t1(i, j) = order.time_s(1, i, j, kN, kN);
  auto notes = [](const io::CsvTable& t) {
    std::vector<std::string> n;
    for (int i = 1; t.meta("note" + std::to_string(i)); ++i)
      n.push_back(*t.meta("note" + std::to_string(i)));
    return n;
  };
  const std::string flags =
      " --refine --no-yaw --pause-s 60 --scan2-order backward "
      "--scan2-y-fastest --rotation-correction auto";
  constexpr int kSeeds = 20;
  int not_worse = 0, halved = 0, refused = 0, thermal_taken = 0, superseded = 0;
  for (std::uint64_t seed = 1601; seed < 1601 + kSeeds; ++seed) {
    core::TwoAxisSimOptions so;
    so.nx = so.ny = kN;
    so.eddy_sensor.noise_sigma_um = kSigma;
    so.contact_sensor.noise_sigma_um = 1.8 * kSigma;
    so.record_s0_scan2 = true;
    so.seed = seed;
    so.timing.sample_period_s = order.sample_period_s;
    so.timing.pause_between_scans_s = order.pause_between_scans_s;
    so.reverse_scan2 = order.reverse_scan2;
    so.y_fastest_scan2 = order.y_fastest_scan2;
    so.diagonal_scan1 = order.diagonal_scan1;
    std::mt19937_64 rng(seed * 131 + 5);
    std::uniform_real_distribution<double> size(1.5 * kSigma, 3.0 * kSigma);
    for (int k : {3, 4})
      so.disturbance.thermal_um[static_cast<std::size_t>(k)] = (rng() % 2 ? 1.0 : -1.0) * size(rng);
    so.disturbance.thermal_tau_s =
        kN * kN *
        std::exp(std::uniform_real_distribution<double>(std::log(0.3), std::log(3.0))(rng));
    const auto sim = core::simulate_two_axis(test::random_two_axis_truth(seed, 0.0), so);
    const std::string name = "diag" + std::to_string(seed);
    const auto csv = dir / (name + ".csv");
    write_two_axis(csv, sim.scan, -1, "", nullptr, &t1);
    std::string out;
    const int rc = run("two-axis" + flags + " --scan1-diagonal -i " + csv.string() + " -o " +
                           (dir / (name + "_w.csv")).string(),
                       &out);
    INFO(out);
    REQUIRE(rc == 0);
    const auto acc =
        io::read_csv(dir / (name + "_w.refine.csv"), {.allow_non_finite = true, .min_rows = 0});
    CHECK(acc.meta("plan").value_or("") == "scan 1 diagonal, scan 2 y fastest, backwards");
    CHECK_THAT(out, Catch::Contains("refine plan: scan 1 diagonal, scan 2 y fastest, backwards"));
    for (const auto& n : notes(acc))
      CHECK(n.find("of sensors 3-4: poorly determined") == std::string::npos);
    for (int s = 1; s <= std::stoi(acc.meta("steps").value_or("0")); ++s)
      thermal_taken +=
          acc.meta("step" + std::to_string(s) + "_effect").value_or("").rfind("thermal", 0) == 0;
    const auto base = io::read_csv(dir / (name + "_w.csv"));
    const auto before = shape_error(base.column("w_um"), sim.w_um);
    const double u_w_base = rms(base.column("u_w_um"));
    const auto refined = io::read_csv(dir / (name + "_w.refined.csv"));
    // Where the refine re-took the rotation decision the other way, the separation's file says
    // so (and the app warns); where it did not, it says nothing.
    const bool differs =
        base.meta("rotation_correction").value() != refined.meta("rotation_correction").value();
    CHECK(base.meta("rotation_superseded").has_value() == differs);
    if (differs) {
      superseded += 1;
      CHECK_THAT(out, Catch::Contains("warning: " + (dir / (name + "_w.csv")).string()));
    }
    const auto after = shape_error(refined.column("w_um"), sim.w_um);
    const double u_w = rms(refined.column("u_w_um"));
    std::printf(
        "two-axis, seed %llu, thermal of sensors 3-4 (%.3f, %.3f um, tau %.0f s), scan 1 "
        "diagonal, scan 2 y fastest backwards: w error %.3f -> %.3f um rms, refined u(w) %.3f "
        "(applied: %s)\n",
        static_cast<unsigned long long>(seed), so.disturbance.thermal_um[3],
        so.disturbance.thermal_um[4], so.disturbance.thermal_tau_s, rms(before), rms(after), u_w,
        acc.meta("applied_any").value_or("?").c_str());
    // Not worse than the separation beyond 2 u(w), u(w) the refined result's own (RMS over the
    // points, as the errors).
    CHECK(rms(after) <= rms(before) + 2 * u_w);
    CHECK(rms(after) <= rms(before) + 2 * u_w_base);
    not_worse += rms(after) <= rms(before) + 2 * u_w;
    halved += rms(after) <= 0.5 * rms(before);

    // The same file declared as the paper's raster scan 1: refused before anything is written.
    const auto wrong = dir / (name + "_raster_w.csv");
    const int rc2 = run("two-axis" + flags + " -i " + csv.string() + " -o " + wrong.string(), &out);
    INFO(out);
    CHECK(rc2 != 0);
    CHECK_THAT(out, Catch::Contains(csv.string() + ": t_scan1_s contradicts the declared scan-1 "
                                                   "plan: declared a raster x fastest"));
    CHECK_THAT(out,
               Catch::Contains("the times read scan 1 along wrapped diagonals (--scan1-diagonal)"));
    CHECK_FALSE(std::filesystem::exists(wrong));
    CHECK_FALSE(std::filesystem::exists(dir / (name + "_raster_w.residuals.csv")));
    refused += rc2 != 0 && !std::filesystem::exists(wrong);
  }
  std::printf(
      "  scan 1 diagonal, %d seeds at sigma %.2f: not worse beyond 2u in %d, halved in %d, "
      "thermal steps taken %d; declared raster refused %d/%d; rotation decision re-taken the "
      "other way (said in w.csv) in %d\n",
      kSeeds, kSigma, not_worse, halved, thermal_taken, refused, kSeeds, superseded);
  // The separation switches the correction on for the drift in most of these runs and the
  // refine, seeing the drift, turns it off: the note is exercised.
  CHECK(superseded > 0);

  // Without t_scan1_s nothing contradicts a declaration: declared raster, the plan the data did
  // not run, the account says sensors 3-4's thermal correction is poorly determined there and
  // names the diagonal plan (the advice the flag above lets a user follow).
  core::TwoAxisSimOptions so;
  so.nx = so.ny = kN;
  so.eddy_sensor.noise_sigma_um = kSigma;
  so.contact_sensor.noise_sigma_um = 1.8 * kSigma;
  so.record_s0_scan2 = true;
  so.seed = 1600;
  const auto sim = core::simulate_two_axis(test::random_two_axis_truth(1600, 0.0), so);
  write_two_axis(dir / "raster.csv", sim.scan);
  std::string out;
  REQUIRE(run("two-axis" + flags + " -i " + (dir / "raster.csv").string() + " -o " +
                  (dir / "raster_w.csv").string(),
              &out) == 0);
  bool said = false;
  for (const auto& n :
       notes(io::read_csv(dir / "raster_w.refine.csv", {.allow_non_finite = true, .min_rows = 0})))
    said = said || (n.rfind("thermal of sensors 3-4: poorly determined", 0) == 0 &&
                    n.find("scan 1 along diagonals") != std::string::npos);
  CHECK(said);
  // Without t_scan1_s the declared plan orders the residuals in time: the second reading of
  // sensor 1's family is (x_1, y_1) along a diagonal, (x_1, y_0) on the raster.
  auto second = [&](const std::string& flag) {
    const std::string stem = flag.empty() ? "order_raster" : "order_diagonal";
    const auto w = dir / (stem + ".csv");
    REQUIRE(run("two-axis --no-yaw" + flag + " -i " + (dir / "raster.csv").string() + " -o " +
                    w.string(),
                &out) == 0);
    const auto t = io::read_csv(dir / (stem + ".residuals.csv"));
    const auto fam = t.column("family"), sen = t.column("sensor"), ord = t.column("order"),
               x = t.column("x_mm"), y = t.column("y_mm");
    for (std::size_t r = 0; r < fam.size(); ++r)
      if (fam[r] == 1 && sen[r] == 1 && ord[r] == 2) return std::pair{x[r], y[r]};
    return std::pair{-1.0, -1.0};
  };
  CHECK(second(" --scan1-diagonal") == std::pair{sim.scan.x_mm(1), sim.scan.y_mm(1)});
  CHECK(second("") == std::pair{sim.scan.x_mm(1), sim.scan.y_mm(0)});
  // And a raster's times declared diagonal are refused the other way round.
  Eigen::MatrixXd t_raster(kN, kN);
  for (int j = 0; j < kN; ++j)
    for (int i = 0; i < kN; ++i)
      t_raster(i, j) = 0.5 * (j * kN + i);
  write_two_axis(dir / "raster_t.csv", sim.scan, -1, "", nullptr, &t_raster);
  CHECK(run("two-axis" + flags + " --scan1-diagonal -i " + (dir / "raster_t.csv").string() +
                " -o " + (dir / "raster_t_w.csv").string(),
            &out) != 0);
  CHECK_THAT(out, Catch::Contains("declared along wrapped diagonals (--scan1-diagonal)"));
  CHECK_THAT(out, Catch::Contains("the times read scan 1 a raster x fastest"));
  CHECK_FALSE(std::filesystem::exists(dir / "raster_t_w.csv"));
  // Times of a raster y fastest (no plan of the refine): refused whichever scan 1 is declared.
  for (int j = 0; j < kN; ++j)
    for (int i = 0; i < kN; ++i)
      t_raster(i, j) = i * kN + j;
  write_two_axis(dir / "y_fastest_t.csv", sim.scan, -1, "", nullptr, &t_raster);
  for (const std::string d : {"", " --scan1-diagonal"}) {
    CHECK(run("two-axis" + flags + d + " -i " + (dir / "y_fastest_t.csv").string() + " -o " +
                  (dir / "y_fastest_t_w.csv").string(),
              &out) != 0);
    CHECK_THAT(out, Catch::Contains("the times read scan 1 as a raster y fastest, then x, a plan "
                                    "the refine does not model"));
    CHECK_FALSE(std::filesystem::exists(dir / "y_fastest_t_w.csv"));
  }
}

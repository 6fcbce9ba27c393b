// errsep-report end to end: a result directory written from closed-form profiles goes in; the
// evaluation, figures, report.html and compensation tables come out.  The Chromium case renders
// the report of the simulated demo scan (Zhao 2019 Eqs. 21-23) to PNG.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <sstream>

#include "errsep/core/iso230.hpp"
#include "errsep/io/csv.hpp"
#include "support/controller_tables.hpp"
#include "support/result_dir.hpp"
#include "support/support.hpp"

namespace fs = std::filesystem;
using errsep::test::app_path;
using errsep::test::run_command;
using errsep::test::TempDir;

namespace {

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string quote(const fs::path& p) {
  return "'" + p.string() + "'";
}

constexpr double kPi = 3.14159265358979323846;

}  // namespace

TEST_CASE("errsep-report evaluates a bow and a sine tilt exactly and writes everything") {
  TempDir tmp;
  const fs::path dir = tmp / "result";
  errsep::test::ResultDirSpec spec;
  spec.travel_mm = 300;  // 61 samples: the midpoint and the quarter points are samples
  const double h = 6.0, tilt = 0.01, a_deg = 0.002;
  spec.S_um = [&](double x) { return 4 * h * (x / 300) * (1 - x / 300) + tilt * x - 1; };
  spec.gamma_deg = [&](double x) { return a_deg * std::sin(2 * kPi * x / 300); };
  spec.refine_unbounded = "u_S unbounded: pe2 not determined by this plan; declare a bound";
  errsep::test::write_four_sensor_result(dir, spec);
  errsep::test::write_grid_csv(
      dir / "surface.csv", 13, 9, 10.0,
      [](double x, double y) { return 0.5 * ((x - 60) / 60) * ((y - 40) / 40) + 0.01 * x; },
      [](double x, double y) { return 0.001 * (x - 60) * (x - 60) + 0.0 * y; },
      [](double x, double) { return 0.002 * (x - 60) * (x - 60); },  // m2x: P-V 7.2 um
      [](double, double y) { return -0.01 * y; });                   // m4y: P-V 0.8 um

  std::string out;
  const int rc = run_command(
      quote(app_path("report")) + " " + quote(dir) +
          " --table-step 10 --local-length 50 --table-param sinumerik_cec.input_axis=X1",
      &out);
  INFO(out);
  REQUIRE(rc == 0);
  for (const char* f :
       {"evaluation.csv", "evaluation.txt", "report.html", "compensation/EYX_sinumerik_cec.ini",
        "compensation/EYX_linuxcnc.hal", "compensation/EYX_beckhoff_crosscomp.lis",
        "compensation/EYX.COM", "compensation/EYX.CMA", "compensation/accuracy.csv",
        "compensation/EYX_table.csv", "plots/straightness.png", "plots/straightness.svg",
        "plots/tilt.png", "plots/reference.png", "plots/residuals.png", "plots/lcurve.png",
        "plots/surface_w.png", "plots/motion_error.png", "plots/compensation.png"})
    CHECK(fs::exists(dir / f));

  // The numbers: a pure bow has straightness h about every reference line (closed form), the
  // sine tilt has an angular deviation of 2 a (its extremes are samples).
  // The surface has no u_w_um: its flatness U is unknown, an empty field, not 0.
  const auto ev = errsep::io::read_csv(dir / "evaluation.csv", {.allow_empty = true});
  CHECK(std::isnan(ev.column("flatness_least_squares_U_um")[0]));
  for (const char* c : {"EYX_end_points_um", "EYX_least_squares_um", "EYX_minimum_zone_um"})
    CHECK(ev.column(c)[0] == Approx(h).epsilon(1e-9));
  CHECK(ev.column("ECX_urad")[0] == Approx(2 * a_deg * errsep::core::kUradPerDeg).epsilon(1e-9));
  CHECK(ev.column("ECX_arcsec")[0] == Approx(2 * a_deg * 3600).epsilon(1e-9));
  // The saddle 0.5 x' y' on a symmetric 13 x 9 grid: flatness 2 * 0.5 for both planes.
  CHECK(ev.column("flatness_least_squares_um")[0] == Approx(1.0).epsilon(1e-9));
  CHECK(ev.column("flatness_minimum_zone_um")[0] == Approx(1.0).epsilon(1e-9));
  // Motion errors of the two tables (Haramiishi 2024 Figs. 18-19) as EZX / EZY peak to valley.
  CHECK(ev.column("EZX_pv_um")[0] == Approx(7.2).epsilon(1e-9));
  CHECK(ev.column("EZY_pv_um")[0] == Approx(0.8).epsilon(1e-9));
  CHECK(fs::exists(dir / "plots/motion_m2x.png"));
  CHECK(fs::exists(dir / "plots/motion_m4y.png"));
  // Uncertainties are propagated (u_S = 0.15 um per point given) and positive.
  CHECK(ev.column("EYX_minimum_zone_U_um")[0] > 0);
  CHECK(ev.column("ECX_U_urad")[0] == Approx(2 * (2.0 + 2.0)));  // bound: k (u_a + u_b)
  // Local straightness of a parabola over 50 mm (10 samples, window midpoints sampled):
  // h (50/300)^2.
  CHECK(ev.column("EYX_local_um")[0] == Approx(h / 36).epsilon(1e-9));
  CHECK(ev.column("local_length_mm")[0] == 50);

  const std::string html = slurp(dir / "report.html");
  CHECK_THAT(html, Catch::Contains("<table id=\"evaluation\">"));
  CHECK_THAT(html, Catch::Contains("<td>EYX</td>"));
  CHECK_THAT(html, Catch::Contains("<td>ECX</td>"));
  CHECK_THAT(html, Catch::Contains("minimum zone"));
  CHECK_THAT(html, Catch::Contains("/data/scans/simulated-demo-scan.csv"));  // raw data file
  CHECK_THAT(html, Catch::Contains("<table id=\"refine\">"));
  // The refine step table read as errsep-refine writes it (nan where not applicable): one row a
  // step, the parameters with u, the residual before -> after.
  {
    const auto at = html.find("<table id=\"refine\">");
    const std::string rt = html.substr(at, html.find("</table>", at) - at);
    CHECK_THAT(rt, Catch::Contains("<td>gain</td>"));
    CHECK_THAT(rt, Catch::Contains("g3 = 0.05 \xC2\xB1 0.002"));
    CHECK_THAT(rt, Catch::Contains("0.31 \xE2\x86\x92 0.26"));
    CHECK_THAT(rt, Catch::Contains("applied: the gain changes S by 0.4 um"));
    CHECK_THAT(rt, !Catch::Contains("nan"));
    CHECK_THAT(rt, !Catch::Contains("error vs truth"));  // no truth in this run: no such column
  }
  // A refined u_S the data do not bound is said so beside the figures, naming the effect.
  CHECK_THAT(html, Catch::Contains("the refined u_S is not bounded by the data"));
  CHECK_THAT(html, Catch::Contains("pe2 not determined by this plan"));
  // The particulars a customer's report states; what the inputs do not say is said so.
  CHECK_THAT(html, Catch::Contains("<table id=\"measurement\">"));
  CHECK_THAT(html, Catch::Contains("ISO 230-1:2012"));
  CHECK_THAT(html, Catch::Contains("none configured: no verdict"));
  CHECK_THAT(html, !Catch::Contains("id=\"verdict\""));
  CHECK_THAT(html, Catch::Contains("Appendix: diagnostics"));
  CHECK_THAT(html, Catch::Contains("<table id=\"configuration\">"));
  CHECK_THAT(html, Catch::Contains("data:image/png;base64,"));
  CHECK_THAT(html, !Catch::Contains("src=\"plots/"));  // self-contained: no external images

  // The tables read back and compensate the measured bow at the table nodes.
  const auto cec =
      errsep::test::parse_sinumerik_cec(slurp(dir / "compensation/EYX_sinumerik_cec.ini"));
  CHECK(cec.input_axis == "(X1)");  // --table-param
  CHECK(cec.output_axis == "(AX2)");
  CHECK(cec.step_mm == 10);
  for (double x = 0; x <= 300; x += 10) {
    const double bow = 4 * h * (x / 300) * (1 - x / 300);  // the end-point line is removed
    CHECK(cec.apply_mm(x) * 1e3 == Approx(-bow).margin(0.5e-3 + 1e-9));  // 1 nm resolution
  }
  // The LinuxCNC HAL file loads into the network model; its lincurves read X and the offsets
  // feed Y.  Each table's interpolation error is printed (and in accuracy.csv).
  const errsep::test::HalNetwork hal(slurp(dir / "compensation/EYX_linuxcnc.hal"));
  for (const auto& [curve, points] : hal.lincurves())
    CHECK(hal.source_of(curve + ".in") == "axis.x.pos-cmd");
  CHECK(hal.connected("axis.y.eoffset-counts"));
  CHECK_THAT(out, Catch::Contains("EYX linuxcnc_hal: EYX_linuxcnc.hal") &&
                      Catch::Contains("interpolation error max"));
  // The result records no machine coordinates: the tables are in scan coordinates, said so.
  CHECK_THAT(out, Catch::Contains("does not record where the scan ran"));

  // Each figure's .gp script runs from where it is written, after the folder has been moved (as
  // a user restyling a figure would run it): it names its data and outputs relative to itself.
  const fs::path moved = tmp / "moved";
  fs::rename(dir, moved);
  int scripts = 0;
  for (const auto& e : fs::directory_iterator(moved / "plots")) {
    if (e.path().extension() != ".gp") continue;
    ++scripts;
    const fs::path png = fs::path(e.path()).replace_extension(".png");
    fs::remove(png);
    std::string gp_out;
    CHECK(run_command("cd " + quote(moved / "plots") + " && gnuplot " + quote(e.path().filename()) +
                          " 2>&1",
                      &gp_out) == 0);
    INFO(e.path() << ": " << gp_out);
    CHECK(fs::exists(png));
  }
  CHECK(scripts >= 10);
}

TEST_CASE("a scan of 2 to 4 points is reported without its local straightness") {
  for (const int points : {2, 3, 4}) {
    TempDir tmp;
    const fs::path dir = tmp / "short";
    errsep::test::ResultDirSpec spec;
    spec.travel_mm = 5.0 * (points - 1);
    spec.reference_mm = spec.travel_mm + 35;
    spec.S_um = [](double x) { return 0.1 * x; };
    errsep::test::write_four_sensor_result(dir, spec);
    std::string out;
    const int rc = run_command(quote(app_path("report")) + " " + quote(dir) + " 2>&1", &out);
    INFO(points << " points: " << out);
    CHECK(rc == 0);
    CHECK_THAT(out, Catch::Contains("is shorter than the sample step 5 mm") &&
                        Catch::Contains("local straightness not evaluated"));
    CHECK(fs::exists(dir / "evaluation.csv"));
    CHECK(fs::exists(dir / "report.html"));
  }
}

TEST_CASE("errsep-report fails with a message and writes nothing for an empty directory") {
  TempDir tmp;
  fs::create_directories(tmp / "empty");
  std::string out;
  const int rc = run_command(quote(app_path("report")) + " " + quote(tmp / "empty"), &out);
  CHECK(rc != 0);
  CHECK_THAT(out, Catch::Contains("no result errsep-report can read: no motion.csv"));
  CHECK_THAT(out, Catch::Contains("no grid CSV (x_mm, y_mm, w_um"));
  CHECK_FALSE(fs::exists(tmp / "empty" / "report.html"));
  CHECK_FALSE(fs::exists(tmp / "empty" / "evaluation.csv"));
  // A folder with raw data only (errsep-scan --no-separate): what to run on it.
  {
    errsep::io::CsvTable raw;
    raw.add_column("x_mm", {0, 5, 10});
    for (const char* c : {"m1_um", "m2_um", "m3_um", "m4_um"})
      raw.add_column(c, {0.1, 0.2, 0.3});
    fs::create_directories(tmp / "rawonly");
    errsep::io::write_csv(tmp / "rawonly" / "raw.csv", raw);
    CHECK(run_command(quote(app_path("report")) + " " + quote(tmp / "rawonly"), &out) != 0);
    CHECK_THAT(out, Catch::Contains("holds a raw four-sensor scan (raw.csv) but no separation: run "
                                    "errsep-separate"));
  }
  // A malformed motion.csv names the file and line.
  std::ofstream(tmp / "empty" / "motion.csv") << "x_mm,S_um\n0,1\n5,abc\n";
  const int rc2 = run_command(quote(app_path("report")) + " " + quote(tmp / "empty"), &out);
  CHECK(rc2 != 0);
  CHECK_THAT(out, Catch::Contains("motion.csv:3"));
  CHECK_FALSE(fs::exists(tmp / "empty" / "report.html"));
}

TEST_CASE("errsep-report evaluates a one-axis displacement result (x_mm, m_um, w_um)") {
  TempDir tmp;
  const fs::path dir = tmp / "disp";
  fs::create_directories(dir);
  errsep::io::CsvTable t;
  t.set_meta("source", "/data/scans/one-axis.csv");
  std::vector<double> x, m, w, r;
  for (int i = 0; i <= 40; ++i) {  // x = 0..200 mm, midpoint 100 mm sampled
    const double xi = 5.0 * i;
    x.push_back(xi);
    m.push_back(4 * 3.0 * (xi / 200) * (1 - xi / 200) + 0.02 * xi);  // bow of 3 um + tilt
    w.push_back(0.01 * xi - 2);                                      // a tilted flat workpiece
    r.push_back(0);
  }
  t.add_column("x_mm", x);
  t.add_column("r_um", r);
  t.add_column("m_um", m);
  t.add_column("w_um", w);
  errsep::io::write_csv(dir / "displacement.csv", t, 15);
  std::string out;
  REQUIRE(run_command(quote(app_path("report")) + " " + quote(dir), &out) == 0);
  INFO(out);
  // No u_m_um / u_w_um: every U is unknown, an empty field (0 would claim an exact value).
  const auto ev = errsep::io::read_csv(dir / "evaluation.csv", {.allow_empty = true});
  for (const char* c : {"EZX_end_points_um", "EZX_least_squares_um", "EZX_minimum_zone_um"}) {
    CHECK(ev.column(c)[0] == Approx(3.0).epsilon(1e-9));
    CHECK(std::isnan(ev.column(std::string(c).replace(std::strlen(c) - 3, 3, "_U_um"))[0]));
  }
  CHECK_THROWS_WITH(errsep::io::read_csv(dir / "evaluation.csv"),
                    Catch::Contains("column 'EZX_end_points_U_um': '' is not a number"));
  CHECK(ev.column("w_minimum_zone_um")[0] == Approx(0).margin(1e-9));
  CHECK(fs::exists(dir / "plots/displacement_profiles.png"));
  CHECK_THAT(slurp(dir / "report.html"), Catch::Contains("/data/scans/one-axis.csv"));
}

// Registered separately (tests/apps/report_app.cmake) with SKIP_RETURN_CODE 77: exits with 77
// and a message when Chromium is not installed, so ctest reports it as skipped, not passed.
TEST_CASE("report of the simulated demo scan renders in headless Chromium", "[chromium]") {
  const fs::path chromium = "/usr/bin/chromium";
  if (!fs::exists(chromium)) {
    std::cout << "SKIPPED: /usr/bin/chromium is not installed (apt-get install chromium); the "
                 "report was not rendered."
              << std::endl;
    std::exit(77);
  }
  TempDir tmp;
  const fs::path dir = tmp / "demo";
  // The simulated demo scan: errsep-simulate (Zhao 2019 Example 1, solved) when it is built,
  // otherwise the closed-form result files of Eqs. (21)-(23).
  std::string sim_out;
  if (fs::exists(app_path("simulate")) &&
      run_command(quote(app_path("simulate")) + " --out " + quote(dir), &sim_out) == 0 &&
      fs::exists(dir / "motion.csv")) {
    std::cout << "demo scan: errsep-simulate --out (Zhao 2019 Example 1)" << std::endl;
  } else {
    std::cout << "demo scan: closed-form result files (errsep-simulate not available)\n"
              << sim_out << std::endl;
    errsep::test::write_four_sensor_result(dir);
  }
  errsep::test::write_grid_csv(
      dir / "surface.csv", 25, 25, 10.0,
      [](double x, double y) { return 3 * std::sin(x / 40) * std::cos(y / 50) + 0.01 * x; },
      [](double x, double y) { return -0.0005 * (x - 120) * (x - 120) + 0.02 * y; });
  std::string out;
  REQUIRE(run_command(quote(app_path("report")) + " " + quote(dir), &out) == 0);
  const fs::path shot = errsep::test::binary_dir() / "report_app_chromium.png";
  fs::remove(shot);
  const std::string flags =
      " --headless --no-sandbox --disable-gpu --disable-quic --no-first-run"
      " --disable-background-networking --disable-component-update --disable-sync"
      " --user-data-dir=" +
      quote(tmp / "profile");
  const std::string url = "file://" + (dir / "report.html").string();
  // The DOM Chromium built from the page holds the evaluation table.
  std::string dom;
  REQUIRE(run_command("timeout 60 " + chromium.string() + flags + " --dump-dom " + quote(url) +
                          " 2>/dev/null",
                      &dom) == 0);
  CHECK_THAT(dom, Catch::Contains("<table id=\"evaluation\">"));
  CHECK_THAT(dom, Catch::Contains("EYX"));
  REQUIRE(run_command("timeout 60 " + chromium.string() + flags + " --screenshot=" + quote(shot) +
                          " --window-size=1200,1600 " + quote(url),
                      &out) == 0);
  INFO(out);
  REQUIRE(fs::exists(shot));
  const std::string png = slurp(shot);
  REQUIRE(png.size() > 33);
  CHECK(png.compare(0, 8, "\x89PNG\r\n\x1a\n") == 0);
  auto be32 = [&](std::size_t off) {
    return (std::uint32_t(std::uint8_t(png[off])) << 24) |
           (std::uint32_t(std::uint8_t(png[off + 1])) << 16) |
           (std::uint32_t(std::uint8_t(png[off + 2])) << 8) |
           std::uint32_t(std::uint8_t(png[off + 3]));
  };
  CHECK(be32(16) == 1200);  // IHDR width
  CHECK(be32(20) == 1600);  // IHDR height
  // A blank 1200 x 1600 page compresses to a few kB; text, tables and plots do not.
  CHECK(png.size() > 50000);
  std::cout << "screenshot: " << shot << " (" << png.size() << " bytes)" << std::endl;
}

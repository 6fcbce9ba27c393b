// End to end over real Modbus TCP on loopback: errsep-scan starts the device simulator
// (errsep-devsim) on an ephemeral port, scans it (one sensor moved to the four configurations by
// the sensor stage, Zhao 2019), writes the raw CSV, separates it; S(x) and γ(x) are compared with
// the truth the simulator plays (Zhao 2019 Example 1, Eqs. 21-22, for the test geometry).
#include <signal.h>

#include <boost/math/distributions/students_t.hpp>
#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <sstream>

#include "errsep/core/four_sensor_model.hpp"
#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/machine_config.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "support/controller_tables.hpp"
#include "support/result_files.hpp"
#include "support/support.hpp"

using namespace errsep;
using errsep::test::app_path;
using errsep::test::run_command;
using errsep::test::TempDir;

namespace {

// The embedded default config, made quicker: a shorter reference (N = 40: P = 33 slide positions,
// 132 points), faster stages.  The zero-adjustment values are set to the form e = b·O + d·O³ that
// the default curvature gauge assumes (a quadratic part of e is not identifiable from the data,
// see core/four_sensor_system.hpp), the same values as core::zhao2019_example1.
std::filesystem::path write_test_config(const TempDir& dir) {
  std::string t = test::quick_simulator_config();
  test::replace_once(t, "N = 69", "N = 40");
  // The shipped config already uses them; the test fails if that changes.
  REQUIRE(t.find("e_um = [0.0, 0.49, 0.92, 0.07]") != std::string::npos);
  const auto path = dir / "machine.toml";
  std::ofstream(path) << t;
  return path;
}

std::string scan_cmd(const std::filesystem::path& cfg, const std::filesystem::path& out) {
  return app_path("scan").string() + " --config " + cfg.string() + " --out " + out.string() +
         " --devsim " + app_path("devsim").string() + " --averages 5 --settle-ms 0";
}

}  // namespace

TEST_CASE("scan on the device simulator, separated: S and gamma match the simulator's truth") {
  TempDir dir;
  const auto cfg_path = write_test_config(dir);
  const auto out = dir / "out";
  std::string output;
  const int rc = run_command(scan_cmd(cfg_path, out), &output);
  INFO(output);
  REQUIRE(rc == 0);
  CHECK_THAT(output, Catch::Contains("listening 127.0.0.1:"));
  CHECK_THAT(output, Catch::Contains("four_sensor scan complete: 132/132 points"));

  // The raw record: complete, nothing lost between the sampling thread and the file.
  const auto raw = io::read_raw_four_sensor_csv(out / "raw.csv");
  CHECK(raw.complete);
  REQUIRE(raw.positions() == 33);
  REQUIRE(raw.geometry);
  CHECK(raw.meta("samples") == raw.meta("samples_consumed"));
  CHECK(raw.meta("overruns") == std::optional<std::string>("0"));
  CHECK(raw.meta("samples_averaged") == std::optional<std::string>("660"));  // 132 points × K 5
  REQUIRE(raw.t_s);

  // The separation, against the truth of the simulator (Zhao 2019 Example 1 for this geometry;
  // x relative to the slide start).
  const auto cfg = io::load_machine_config(cfg_path);
  const auto truth = core::zhao2019_example1(cfg.scan.geometry);
  const auto motion = io::read_csv(out / "motion.csv");
  const auto x = motion.column("x_mm");
  const auto S = motion.column("S_um");
  const auto g = motion.column("gamma_urad");
  const auto uS = motion.column("u_S_um");
  const auto ug = motion.column("u_gamma_urad");
  REQUIRE(x.size() == 33);
  // Bounds from the run's own stated uncertainty (issue 15): every point within k·u of the truth,
  // k the simultaneous factor for all points of S (and of γ) at a family-wise false-alarm rate of
  // 10⁻³: Bonferroni over the P points with Student's t at σ̂'s degrees of freedom (u is σ̂ times
  // a known matrix).  A fixed k = 4 was crossed by chance: over 200 simulated runs of this
  // geometry and noise (σ̂ from 27 dof, 33 points) the largest |S − S_true|/u_S of a run has
  // p99 3.9 and max 4.2 (γ 3.6 and 3.9), and the scan on the simulator reached 4.00 once in 60.
  // The coverage of u itself (about 95 % within 2u) is tested over random profiles in
  // tests/core/four_sensor_coverage.  γ is determined up to the constant e_4/(D2+D3+D4)
  // (Eq. 19): e_4 = 0.07 µm here, which the simulator plays and the gauge e_4 = 0 moves into γ as
  // a constant e_4/O_4, known exactly.
  const auto dof_meta = motion.meta_number("sigma_hat_dof");
  REQUIRE(dof_meta);
  const double dof = *dof_meta;
  REQUIRE(dof >= 5);
  const double family_alpha = 1e-3;
  const double k = boost::math::quantile(boost::math::complement(
      boost::math::students_t(dof), family_alpha / (2.0 * static_cast<double>(x.size()))));
  const auto& off = cfg.scan.geometry.offsets_mm();
  const double dg_const = 1e6 * cfg.simulator.e_um[3] / (1000.0 * off[3]);
  double worst_S = 0, worst_g = 0, max_dS = 0, max_dg = 0;
  for (std::size_t n = 0; n < x.size(); ++n) {
    REQUIRE(uS[n] > 0);
    REQUIRE(ug[n] > 0);
    const double dS = S[n] - truth.S_um(x[n]);
    const double dg = g[n] - 1e6 * truth.gamma_rad(x[n]) - dg_const;
    max_dS = std::max(max_dS, std::fabs(dS));
    max_dg = std::max(max_dg, std::fabs(dg));
    worst_S = std::max(worst_S, std::fabs(dS) / uS[n]);
    worst_g = std::max(worst_g, std::fabs(dg) / ug[n]);
  }
  std::printf(
      "scan end to end: max |S - S_true| = %.3f um, largest |S - S_true|/u_S = %.2f; "
      "max |gamma - gamma_true| = %.3f urad, largest |gamma - gamma_true|/u_gamma = %.2f; "
      "simultaneous k = %.2f (sigma_hat dof %.0f)\n",
      max_dS, worst_S, max_dg, worst_g, k, dof);
  CHECK(worst_S <= k);
  CHECK(worst_g <= k);

  // The demo's HEIDENHAIN table (io/cnc/heidenhain_com.hpp cites the TNC manuals), read back by
  // an independent reader: column Y of EYX.COM at the machine positions of X, entered in column
  // X of EYX.CMA; the values are -(S less its end-point line) in mm with 4 decimals.
  std::string rep;
  const int rrc = run_command(app_path("report").string() + " " + out.string() + " --config " +
                                  cfg_path.string() + " --no-plots",
                              &rep);
  INFO(rep);
  REQUIRE(rrc == 0);
  const auto com = test::parse_heidenhain_com(test::read_file(out / "compensation" / "EYX.COM"));
  const auto cma = test::parse_heidenhain_cma(test::read_file(out / "compensation" / "EYX.CMA"));
  CHECK(com.axis == 'Y');
  CHECK(cma.column == "X");
  CHECK(cma.com_path == "TNC:\\table\\EYX.COM");
  CHECK(cma.active);
  REQUIRE(com.axispos_mm.size() == x.size());
  const double start = cfg.scan.slide_start_mm;
  for (std::size_t n = 0; n < x.size(); ++n) {
    const double line =
        S.front() + (S.back() - S.front()) * (x[n] - x.front()) / (x.back() - x.front());
    CHECK(com.axispos_mm[n] == Approx(start + x[n]).margin(1e-4));
    CHECK(com.value_mm[n] * 1e3 == Approx(-(S[n] - line)).margin(0.05 + 1e-9));
  }
}

TEST_CASE("SIGINT during the scan: stages stopped, raw data kept and marked incomplete, exit 130") {
  TempDir dir;
  const auto cfg_path = write_test_config(dir);
  const auto out = dir / "out";
  // Interrupt once the scan reports 20 % of its points, not after a fixed time: a CI run once
  // finished the whole scan within the 2 s this test used to wait.  The scan gets 50 readings per
  // point here (~10x longer than the 2 s scan above), so 20 % leaves it far from done.  The
  // simulator runs in its own process group, so only the scan gets the signal, as with Ctrl-C.
  std::string slow = scan_cmd(cfg_path, out);
  slow.replace(slow.find("--averages 5"), 12, "--averages 50");
  const auto log = dir / "scan.log";
  const std::string cmd = "sh -c '" + slow + " > " + log.string() +
                          " 2>&1 & pid=$!; i=0; while ! grep -q \"(20%)\" " + log.string() +
                          " && [ $i -lt 600 ]; do sleep 0.05; i=$((i+1)); done; kill -INT $pid; "
                          "wait $pid; echo exit=$?; cat " +
                          log.string() + "'";
  std::string output;
  REQUIRE(run_command(cmd, &output) == 0);
  INFO(output);
  CHECK_THAT(output, Catch::Contains("exit=130"));
  CHECK_THAT(output, Catch::Contains("aborted by user"));
  CHECK_THAT(output, Catch::Contains("stages stopped"));
  CHECK_FALSE(std::filesystem::exists(out / "motion.csv"));  // nothing separated
  CHECK_THROWS_WITH(io::read_raw_four_sensor_csv(out / "raw.csv"), Catch::Contains("incomplete"));
  io::RawReadOptions inspect;
  inspect.require_complete = false;
  const auto raw = io::read_raw_four_sensor_csv(out / "raw.csv", inspect);
  CHECK_FALSE(raw.complete);
  CHECK(raw.meta("outcome") == std::optional<std::string>("aborted"));
  // Some points were measured and kept; the ones not reached are nan.
  CHECK(std::isfinite(raw.m_um[0][0]));
  CHECK(std::isnan(raw.m_um[3].back()));
  CHECK(raw.meta("samples") == raw.meta("samples_consumed"));
}

// errsep-scan --method displacement --refine (issue 16 item 4 in the pipeline): the displacement
// pipeline runs its loop (core/displacement_refine_one_axis.hpp) and writes its account
// (refine/displacement_refine.csv: effect, decision, size ± u, the predicted errors of w) and the
// refined profile (refine/displacement.csv) into the same result set; the report shows the
// account as a table; errsep-report reads the folder.  errsep-scan's displacement scan runs scan
// 2 in the order of scan 1 by default (the paper), so a linear drift of the sensors is named "not
// identifiable from this plan" and nothing is applied for it, with or without one; with
// --scan2-order backward the raw file records the order and the drift is identified.  A thermal
// drift of the workpiece sensor (not linear in time: it shows in the paper's plan), added to a
// recorded scan at its recorded times, is named and corrected by errsep-separate-displacement
// one-axis --refine, the same loop.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <regex>
#include <string>
#include <utility>
#include <vector>

#include "errsep/io/csv.hpp"
#include "errsep/io/machine_config.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "errsep/io/staged_directory.hpp"
#include "support/result_files.hpp"
#include "support/support.hpp"

using namespace errsep;
using errsep::test::app_path;
using errsep::test::rms_shape;
using errsep::test::run_command;
using errsep::test::TempDir;
namespace fs = std::filesystem;

namespace {

/// The account's steps and notes, so that a failure says what the refine found.
std::string account_steps(const io::CsvTable& account) {
  std::string steps;
  for (const auto& [k, v] : account.metadata)
    if (k.rfind("step", 0) == 0 || k.rfind("note", 0) == 0) steps += k + ": " + v + "\n";
  return steps;
}

/// The device simulator drifts its sensors linearly in its own time; the readings' recorded times
/// carry the loaded machine's scheduling jitter, and on a scan of a few seconds the library's
/// first-order thermal drift (one parameter more, counted by AIC) can then fit sensor 1's drift as
/// well (seen in CI under load: the same in apps/daemon_displacement).  Either form is the drift of
/// sensor 1; which of the two is not what these cases are about.
bool is_drift_of_sensor_1(const std::string& effect) {
  return effect == "drift of sensor 1" || effect.rfind("thermal drift of sensor 1 (", 0) == 0;
}

/// The embedded default config with faster stages; `drift` µm/s on every simulated sensor.
fs::path write_test_config(const TempDir& dir, double drift) {
  std::string cfg = test::quick_simulator_config();
  cfg = std::regex_replace(cfg, std::regex("drift_um_per_s = [-0-9.e]+"),
                           "drift_um_per_s = " + std::to_string(drift));
  const auto path = dir / "machine.toml";
  std::ofstream(path) << cfg;
  return path;
}

std::string scan_cmd(const fs::path& cfg, const fs::path& out) {
  return app_path("scan").string() + " --config " + cfg.string() + " --out " + out.string() +
         " --devsim " + app_path("devsim").string() +
         " --method displacement --refine --averages 5 --settle-ms 0 --no-mqtt --no-pdf";
}

/// Runs the scan and checks what every refined displacement result holds; returns the account.
io::CsvTable scan_and_check(const TempDir& dir, double drift) {
  const auto cfg = write_test_config(dir, drift);
  REQUIRE_THAT(test::read_file(cfg), Catch::Contains("drift_um_per_s = " + std::to_string(drift)));
  const fs::path out = dir / "out";
  std::string output;
  const int rc = run_command(scan_cmd(cfg, out), &output);
  INFO(output);
  REQUIRE(rc == 0);
  CHECK_THAT(output, Catch::Contains("displacement refine (one axis)"));
  for (const char* f : {"displacement.csv", "refine/displacement_refine.csv",
                        "refine/displacement.csv", "report/report.html"}) {
    INFO(f);
    CHECK(fs::exists(out / f));
  }
  CHECK(io::check_result_set(out).whole());

  // The account: its columns (units in the names) and the drift the plan cannot identify.
  const auto t =
      io::read_csv(out / "refine" / "displacement_refine.csv", {.allow_non_finite = true});
  for (const char* c : {"step", "value", "u", "F", "p_value", "applied", "w_change_rms_um",
                        "w_error_without_rms_um", "w_u_if_applied_rms_um", "u_w_added_rms_um"}) {
    INFO(c);
    CHECK(t.find_column(c));
  }
  CHECK(t.meta("source") == std::optional<std::string>((out / "raw_displacement.csv").string()));
  INFO(account_steps(t));
  CHECK(is_drift_of_sensor_1(t.meta("step1_effect").value_or("(none)")));
  CHECK(t.meta("step1_decision") == std::optional<std::string>("not identifiable"));
  CHECK_THAT(t.meta("step1_line").value_or(""), Catch::Contains("run scan 2 backwards"));

  // The refined profile: the same grid, u at least the separation's (nothing applied: the same
  // w), and where it came from.
  const auto base = io::read_csv(out / "displacement.csv");
  const auto ref = io::read_csv(out / "refine" / "displacement.csv");
  REQUIRE(ref.rows.size() == base.rows.size());
  CHECK(ref.meta("refine").has_value());
  const auto ub = base.column("u_w_um"), ur = ref.column("u_w_um");
  const auto wb = base.column("w_um"), wr = ref.column("w_um");
  for (std::size_t k = 0; k < ub.size(); ++k) {
    CHECK(ur[k] >= ub[k] * (1 - 1e-12));
    CHECK(wr[k] == Approx(wb[k]).margin(1e-9));
  }

  // The report shows the account as a table, and errsep-report reads the folder.
  const std::string html = test::read_file(out / "report" / "report.html");
  CHECK_THAT(html, Catch::Contains("displacement_refine"));
  CHECK_THAT(html, Catch::Contains("drift of sensor 1"));
  CHECK_THAT(html, Catch::Contains("not identifiable"));
  std::string rep;
  const int rrc =
      run_command(app_path("report").string() + " " + out.string() + " --no-plots", &rep);
  INFO(rep);
  CHECK(rrc == 0);
  return t;
}

}  // namespace

TEST_CASE(
    "scan --method displacement --refine: the loop's account, the refined profile, the "
    "report's table") {
  TempDir dir;
  const auto t = scan_and_check(dir, 0.0);
  // Clean: nothing taken, only the plan's limits stated.
  CHECK(t.meta("applied_any") == std::optional<std::string>("false"));
  CHECK(t.meta("steps") == std::optional<std::string>("1"));
}

TEST_CASE(
    "scan --method displacement --refine with drifting sensors: the drift is named not "
    "identifiable from this plan, nothing applied") {
  TempDir dir;
  const auto t = scan_and_check(dir, 0.05);
  CHECK(t.meta("applied_any") == std::optional<std::string>("false"));
}

TEST_CASE(
    "separate-displacement one-axis --refine: a thermal drift of the workpiece sensor added "
    "to a recorded scan is named, corrected and w comes nearer the drift-free separation") {
  TempDir dir;
  const auto cfg = write_test_config(dir, 0.0);
  const fs::path out = dir / "out";
  std::string output;
  REQUIRE(run_command(app_path("scan").string() + " --config " + cfg.string() + " --out " +
                          out.string() + " --devsim " + app_path("devsim").string() +
                          " --method displacement --averages 5 --settle-ms 0 --no-mqtt "
                          "--no-report",
                      &output) == 0);
  // Sensor 1 warms up: + a(1 - exp(-t/tau)) at the times the scan recorded, tau a quarter of the
  // scan.
  auto raw = io::read_raw_displacement_csv(out / "raw_displacement.csv");
  REQUIRE(raw.t_scan1_s);
  REQUIRE(raw.t_scan2_s);
  const double tau = 0.25 * raw.t_scan2_s->back(), a = 1.0;
  for (std::size_t k = 0; k < raw.x_mm.size(); ++k) {
    raw.s1_scan1_um[k] += a * (1 - std::exp(-(*raw.t_scan1_s)[k] / tau));
    raw.s1_scan2_um[k] += a * (1 - std::exp(-(*raw.t_scan2_s)[k] / tau));
  }
  io::write_raw_displacement_csv(dir / "thermal.csv", raw);

  const std::string sep = app_path("separate-displacement").string() + " one-axis -i ";
  std::string o1, o2;
  REQUIRE(run_command(
              sep + (out / "raw_displacement.csv").string() + " -o " + (dir / "clean.csv").string(),
              &o1) == 0);
  const int rc = run_command(sep + (dir / "thermal.csv").string() + " -o " +
                                 (dir / "thermal_res.csv").string() + " --refine",
                             &o2);
  INFO(o2);
  REQUIRE(rc == 0);
  const auto t = io::read_csv(dir / "thermal_res.refine.csv", {.allow_non_finite = true});
  bool named = false;
  for (int s = 1; s <= std::stoi(t.meta("steps").value_or("0")); ++s) {
    const auto e = t.meta("step" + std::to_string(s) + "_effect").value_or("");
    const auto d = t.meta("step" + std::to_string(s) + "_decision").value_or("");
    named = named || (e.rfind("thermal drift of sensor 1", 0) == 0 && d != "not identifiable");
  }
  CHECK(named);
  // Against the separation of the scan without the drift: the refined w is nearer than the
  // uncorrected one (at most half its error), and within 4 u of the refined result at every point.
  const auto clean = io::read_csv(dir / "clean.csv");
  const auto before = io::read_csv(dir / "thermal_res.csv");
  const auto after = io::read_csv(dir / "thermal_res.refined.csv");
  const auto wc = clean.column("w_um"), wb = before.column("w_um"), wa = after.column("w_um"),
             ua = after.column("u_w_um");
  const double eb = rms_shape(wb, wc), ea = rms_shape(wa, wc);
  std::printf(
      "thermal drift of sensor 1, a = %.2f um, tau = %.2f s: w error (RMS, shape) %.4f -> "
      "%.4f um\n",
      a, tau, eb, ea);
  CHECK(ea <= 0.5 * eb);  // halved (measured 0.12 -> 0.011-0.018 um in 6 runs)
  double mean = 0;
  for (std::size_t k = 0; k < wa.size(); ++k)
    mean += (wa[k] - wc[k]) / static_cast<double>(wa.size());
  for (std::size_t k = 0; k < wa.size(); ++k)
    CHECK(std::abs(wa[k] - wc[k] - mean) <= 4 * ua[k]);
}

namespace {

/// errsep-scan --method displacement (no separation) in the given scan-2 order; returns the raw
/// scan it recorded.
io::RawDisplacementScan record_scan(const TempDir& dir, const std::string& name,
                                    const std::string& order) {
  const auto cfg = write_test_config(dir, 0.0);
  const fs::path out = dir / name;
  std::string output;
  const int rc = run_command(app_path("scan").string() + " --config " + cfg.string() + " --out " +
                                 out.string() + " --devsim " + app_path("devsim").string() +
                                 " --method displacement --scan2-order " + order +
                                 " --averages 5 --settle-ms 0 --no-mqtt --no-report",
                             &output);
  INFO(output);
  REQUIRE(rc == 0);
  return io::read_raw_displacement_csv(out / "raw_displacement.csv");
}

struct DriftRun {
  double w_error_um = 0;         ///< RMS (shape) of w against the drift-free separation of the scan
  double w_error_before_um = 0;  ///< the same of the drifted scan's separation, not refined
  double u_w_rms_um = 0;         ///< RMS of the refined u(w)
  io::CsvTable account;          ///< <out>.refine.csv
};

/// Adds a linear drift `v` um/s of the workpiece sensor 1 to a recorded scan at its recorded
/// times, separates the scan with and without it (errsep-separate-displacement one-axis
/// --refine) and compares the refined w with the drift-free one.
DriftRun add_drift_and_refine(const TempDir& dir, const std::string& name,
                              io::RawDisplacementScan raw, double v) {
  const fs::path clean = dir / (name + "_clean.csv"), drifted = dir / (name + "_drift.csv");
  io::write_raw_displacement_csv(clean, raw);
  for (std::size_t k = 0; k < raw.x_mm.size(); ++k) {
    raw.s1_scan1_um[k] += v * (*raw.t_scan1_s)[k];
    raw.s1_scan2_um[k] += v * (*raw.t_scan2_s)[k];
  }
  io::write_raw_displacement_csv(drifted, raw);
  const std::string sep = app_path("separate-displacement").string() + " one-axis -i ";
  std::string o1, o2;
  REQUIRE(run_command(sep + clean.string() + " -o " + (dir / (name + "_c.csv")).string(), &o1) ==
          0);
  const int rc = run_command(
      sep + drifted.string() + " -o " + (dir / (name + "_d.csv")).string() + " --refine", &o2);
  INFO(o2);
  REQUIRE(rc == 0);
  DriftRun r;
  r.account = io::read_csv(dir / (name + "_d.refine.csv"), {.allow_non_finite = true});
  const auto wc = io::read_csv(dir / (name + "_c.csv")).column("w_um");
  const auto wa = io::read_csv(dir / (name + "_d.refined.csv")).column("w_um");
  r.w_error_um = rms_shape(wa, wc);
  r.w_error_before_um = rms_shape(io::read_csv(dir / (name + "_d.csv")).column("w_um"), wc);
  const auto ua = io::read_csv(dir / (name + "_d.refined.csv")).column("u_w_um");
  double u2 = 0;
  for (const double u : ua)
    u2 += u * u;
  r.u_w_rms_um = ua.empty() ? 0.0 : std::sqrt(u2 / static_cast<double>(ua.size()));
  return r;
}

}  // namespace

TEST_CASE(
    "scan --scan2-order backward: a linear drift of the workpiece sensor is identified and its "
    "error of w halved, and with the paper order named not identifiable from this plan") {
  TempDir dir;
  const auto fwd = record_scan(dir, "forward", "forward");
  const auto bwd = record_scan(dir, "backward", "backward");
  // The raw file records the order of scan 2 and its times run that way.
  CHECK(fwd.scan2_order == core::DisplacementScanOrder::forward);
  REQUIRE(bwd.scan2_order == core::DisplacementScanOrder::backward);
  REQUIRE(bwd.t_scan2_s);
  REQUIRE(fwd.t_scan2_s);
  CHECK(bwd.t_scan2_s->front() > bwd.t_scan2_s->back());
  CHECK(fwd.t_scan2_s->front() < fwd.t_scan2_s->back());
  CHECK(bwd.t_scan2_s->back() > bwd.t_scan1_s->back());  // scan 2 after scan 1

  // A drift of 1 um over the scan pair, whatever the machine's speed.
  const double v = 1.0 / bwd.t_scan2_s->front();
  const auto f = add_drift_and_refine(dir, "forward", fwd, v);
  const auto b = add_drift_and_refine(dir, "backward", bwd, v);
  std::printf(
      "linear drift of sensor 1, %.3g um/s: w error (RMS, shape) forward %.3g um, backward "
      "%.3g um\n",
      v, f.w_error_um, b.w_error_um);

  // The paper's order: named not identifiable, nothing applied.
  // The drift is exactly linear in the recorded times, but the library's first-order thermal
  // drift nests it (tau -> infinity) with one parameter more: AIC takes the nesting form when the
  // noise favours it by more than its penalty (chi2_1 > 2: about one run in six). Either form is
  // the drift of sensor 1; the rate is checked where the linear form was taken.
  INFO("forward:\n" << account_steps(f.account) << "backward:\n" << account_steps(b.account));
  CHECK(is_drift_of_sensor_1(f.account.meta("step1_effect").value_or("(none)")));
  CHECK(f.account.meta("step1_decision") == std::optional<std::string>("not identifiable"));
  CHECK_THAT(f.account.meta("step1_line").value_or(""), Catch::Contains("run scan 2 backwards"));
  // Nothing is applied for the drift; but the recorded times carry the machine's timing jitter,
  // and on a loaded machine (p99 5 ms in a 17 ms period) a 1 um drift leaves a few tens of nm
  // in the workpiece repeat, which a short thermal drift can fit and the decision may apply (seen
  // 1 run in 6 under 3 parallel scans).  Whatever it applies must not make w worse beyond its u.
  std::printf("forward: applied %s, w error %.3g -> %.3g um (u(w) rms %.3g um)\n",
              f.account.meta("applied_any").value_or("?").c_str(), f.w_error_before_um,
              f.w_error_um, f.u_w_rms_um);
  CHECK(f.w_error_um <= f.w_error_before_um + 2 * f.u_w_rms_um);

  // Backward: identified (taken by the F-test, not "not identifiable"), its rate within 4 u of
  // the injected one, and w's error at most half the paper order's.
  const std::string effect = b.account.meta("step1_effect").value_or("(none)");
  CHECK(is_drift_of_sensor_1(effect));
  const auto d = b.account.meta("step1_decision").value_or("");
  CHECK((d == "applied" || d == "detected, not applied"));
  const auto val = b.account.column("value"), u = b.account.column("u");
  REQUIRE(!val.empty());
  std::printf("backward: %s %.4g +- %.2g (injected %.4g um/s), decision %s\n", effect.c_str(),
              val[0], u[0], v, d.c_str());
  if (effect == "drift of sensor 1") CHECK(std::abs(val[0] - v) <= 4 * u[0]);
  CHECK(b.w_error_um <= 0.5 * f.w_error_um);
}

TEST_CASE(
    "scan --scan2-order backward with every simulated sensor drifting: the drift is detected and "
    "the refined u(w) covers the simulated machine's w") {
  // The device simulator drifts every sensor alike (0.2 um/s): sensor 2's share goes into r, m
  // and w, and no two scans identify it.  With scan 2 backwards sensor 1's drift is detected and
  // the same on sensor 2 is carried into u (core/displacement_refine_one_axis.hpp); with the
  // paper's order nothing is detected and nothing can widen u (printed, for comparison).
  TempDir dir;
  const auto cfg_path = write_test_config(dir, 0.2);
  const auto cfg = io::load_machine_config(cfg_path);
  auto check = [&](const std::string& order) {
    const fs::path out = dir / order;
    std::string output;
    const int rc = run_command(scan_cmd(cfg_path, out) + " --scan2-order " + order, &output);
    INFO(output);
    REQUIRE(rc == 0);
    const auto t = io::read_csv(out / "refine" / "displacement.csv");
    const auto x = t.column("x_mm"), w = t.column("w_um"), u = t.column("u_w_um");
    // The gauge r(x_1) = 0 (Eq. 9) moves m by the true r(x_1) and w by minus it.
    const double gauge = cfg.simulator.r_um.eval(x.front());
    int within = 0;
    double worst = 0;
    for (std::size_t k = 0; k < x.size(); ++k) {
      const double z = std::abs(w[k] - cfg.simulator.w_um.eval(x[k]) + gauge) / u[k];
      within += z <= 4;
      worst = std::max(worst, z);
    }
    std::printf(
        "drift 0.2 um/s on every sensor, scan 2 %s: refined w within 4 u at %d/%zu "
        "points (worst %.2f u)\n",
        order.c_str(), within, x.size(), worst);
    return std::pair{
        within == static_cast<int>(x.size()),
        io::read_csv(out / "refine" / "displacement_refine.csv", {.allow_non_finite = true})};
  };
  const auto [covered, account] = check("backward");
  INFO(account_steps(account));
  CHECK(is_drift_of_sensor_1(account.meta("step1_effect").value_or("(none)")));
  CHECK(account.meta("step1_decision") != std::optional<std::string>("not identifiable"));
  CHECK(covered);
  (void)check("forward");
}

TEST_CASE(
    "scan --method displacement --refine without drift, five simulator seeds, both scan 2 "
    "orders: coverage of the refined u(w)",
    "[sweep]") {
  // The simulated machine's noise only (no drift): nothing should be applied, and the refined
  // u(w) (the separation's when nothing is taken) should cover the machine's w at about 95 % of
  // the points within 2u.  Five seeds x two orders, ~1.2 s a scan (~12 s).  Coverage is printed,
  // not asserted: the simulator's readings depend on when they are sampled (jitter, missed
  // periods under load), so a seed does not fix the noise, and a scan's 25 points share one σ̂
  // (24 dof) and the random walk of Eq. (9): one scan covers 25/25 or 10/25 (the paper order's
  // seed 3 gave 10, 25 and — pooled with the others — 110, 125 and 118 of 125 in three runs).
  // Clean runs where a correction is applied are asserted at most 1 of 10 (issue 16: <= 5 %).
  TempDir dir;
  int applied_total = 0;
  for (const char* order : {"forward", "backward"}) {
    long within = 0, points = 0;
    int applied = 0;
    for (int seed = 1; seed <= 5; ++seed) {
      std::string cfg = test::quick_simulator_config();
      cfg =
          std::regex_replace(cfg, std::regex("drift_um_per_s = [-0-9.e]+"), "drift_um_per_s = 0.0");
      cfg = std::regex_replace(cfg, std::regex("\nseed = [0-9]+"),
                               "\nseed = " + std::to_string(seed));
      const fs::path cfg_path = dir / ("machine" + std::to_string(seed) + ".toml");
      std::ofstream(cfg_path) << cfg;
      REQUIRE_THAT(test::read_file(cfg_path), Catch::Contains("seed = " + std::to_string(seed)));
      const auto mc = io::load_machine_config(cfg_path);
      const fs::path out = dir / (std::string(order) + std::to_string(seed));
      std::string output;
      const int rc =
          run_command(scan_cmd(cfg_path, out) + " --scan2-order " + std::string(order), &output);
      INFO(output);
      REQUIRE(rc == 0);
      const auto t = io::read_csv(out / "refine" / "displacement.csv");
      // No rows when nothing is taken and the plan identifies every effect (backwards).
      const auto account = io::read_csv(out / "refine" / "displacement_refine.csv",
                                        {.allow_non_finite = true, .min_rows = 0});
      applied += account.meta("applied_any") == std::optional<std::string>("true");
      const auto x = t.column("x_mm"), w = t.column("w_um"), u = t.column("u_w_um");
      const double gauge = mc.simulator.r_um.eval(x.front());  // r(x_1) = 0 (Eq. 9)
      int in = 0;
      for (std::size_t k = 0; k < x.size(); ++k)
        in += std::abs(w[k] - mc.simulator.w_um.eval(x[k]) + gauge) <= 2 * u[k];
      std::printf("clean, scan 2 %s, seed %d: refined w within 2u at %d/%zu points\n", order, seed,
                  in, x.size());
      within += in;
      points += static_cast<long>(x.size());
    }
    std::printf("clean, scan 2 %s: within 2u at %ld/%ld points, applied in %d/5\n", order, within,
                points, applied);
    applied_total += applied;
  }
  CHECK(applied_total <= 1);
}

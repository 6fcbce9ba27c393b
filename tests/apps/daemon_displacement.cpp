// errsep-daemon with [scan] method = "displacement" (issue 17: the displacement scan through the
// same pipeline in errsep-scan and the daemon): the daemon's scan, triggered through its register
// map, writes the result folder errsep-scan writes for the same machine (raw_displacement.csv,
// displacement.csv, displacement_residuals.csv, report/ with the same file names and the same CSV
// columns), both whole result sets that errsep-report reads; the register map shows the
// straightness of m(x) with its U.  Then a folder committed without its report (what a kill
// between the commit of the results and the report leaves; made here with --no-report) gets its
// report at the daemon's next start, and the journal says so.  With [refine] enabled and scan 2
// backwards (issue 16 item 4), the daemon's folder holds the loop's account and refined profile,
// and a drift of the simulated sensors is taken as identifiable.
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include "errsep/io/csv.hpp"
#include "errsep/io/staged_directory.hpp"
#include "support/daemon_rig.hpp"
#include "support/result_files.hpp"

using namespace errsep;
using namespace std::chrono_literals;
namespace fs = std::filesystem;
using errsep::test::files_under;

namespace {

/// The shipped simulator config as a displacement machine: quick stages, K = 5, no PDF.
fs::path write_config(const fs::path& dir) {
  std::string t = test::quick_simulator_config();
  test::replace_once(t, "method = \"four_sensor\"", "method = \"displacement\"");
  test::replace_once(t, "averages = 100", "averages = 5");
  t += "\n[report]\npdf = false\n";
  const fs::path p = dir / "machine.toml";
  std::ofstream(p) << t;
  return p;
}

}  // namespace

TEST_CASE(
    "displacement: the daemon writes errsep-scan's folder, a lost report is remade at start") {
  test::DaemonRig rig;
  rig.config = write_config(rig.tmp.path());
  rig.devsim.start(rig.config, rig.tmp / "devsim.log");
  rig.start_daemon();
  REQUIRE(rig.notify->wait_for("READY=1", 15s));
  const auto r = rig.trigger_and_wait(1, 60s);
  REQUIRE(r[test::reg_last_outcome] == 1);  // complete
  // The straightness of the table motion error m(x), with its U.
  const double mz = test::nm_registers_um(r, test::reg_straightness_hi);
  const double mz_U = test::nm_registers_um(r, test::reg_straightness_U_hi);
  CHECK((std::isfinite(mz) && mz > 0));
  CHECK((std::isfinite(mz_U) && mz_U > 0));
  REQUIRE(rig.find_file(1, "result"));
  const auto folder = rig.result_folder(1);
  REQUIRE(folder);
  const fs::path daemon_dir = *folder;
  rig.daemon->signal(SIGTERM);
  REQUIRE(rig.daemon->wait(10s));

  const fs::path scan_dir = rig.tmp / "scan";
  std::string scan_out;
  const int rc =
      test::run_command(test::app_path("scan").string() + " --config " + rig.config.string() +
                            " --out " + scan_dir.string() + " --devsim " +
                            test::app_path("devsim").string() + " --settle-ms 0 --no-mqtt",
                        &scan_out);
  INFO(scan_out);
  REQUIRE(rc == 0);

  CHECK(test::check_same_result_files(daemon_dir, scan_dir) >= 4);
  const auto daemon_files = files_under(daemon_dir);
  for (const char* f : {"raw_displacement.csv", "displacement.csv", "displacement_residuals.csv",
                        "report/evaluation.csv", "report/evaluation.txt", "report/report.html"}) {
    INFO(f);
    CHECK(daemon_files.count(f) == 1);
  }
  // The daemon's result carries its uncertainty and its source, as errsep-scan's.
  const auto t = io::read_csv(daemon_dir / "displacement.csv");
  CHECK(t.find_column("u_w_um"));
  CHECK(t.meta("source") ==
        std::optional<std::string>((daemon_dir / "raw_displacement.csv").string()));
  for (const fs::path& dir : {daemon_dir, scan_dir})
    test::check_report_reads(dir);

  // A report lost to a stop between the commit of a scan's results and its report: the daemon
  // with --no-report leaves exactly that folder (results committed, no report/).
  rig.start_daemon({"--no-report"});
  // Idle (READY=1 of the first start is still among the notify socket's messages).
  REQUIRE(rig.wait_regs([](const std::vector<long>& x) { return x[0] == 1; }, 15s).size() ==
          test::kRegisterCount);
  const auto r2 = rig.trigger_and_wait(2, 60s);
  REQUIRE(r2[test::reg_last_outcome] == 1);
  const auto folder2 = rig.result_folder(2);
  REQUIRE(folder2);
  const fs::path dir2 = *folder2;
  REQUIRE(fs::exists(dir2 / "displacement.csv"));
  REQUIRE_FALSE(fs::exists(dir2 / "report"));
  const auto before = files_under(dir2);
  rig.daemon->signal(SIGTERM);
  REQUIRE(rig.daemon->wait(10s));

  // The next start makes it (before the register map listens), says so, and keeps the scan's
  // files; the folder with its report already is left alone.
  const auto first_report_time = fs::last_write_time(daemon_dir / "report" / "report.html");
  rig.start_daemon();
  CHECK(fs::exists(dir2 / "report" / "report.html"));
  CHECK(fs::exists(dir2 / "report" / "evaluation.csv"));
  CHECK(io::check_result_set(dir2).whole());
  const auto after = files_under(dir2);
  for (const auto& f : before) {
    INFO(f);
    CHECK(after.count(f) == 1);
  }
  CHECK(fs::last_write_time(daemon_dir / "report" / "report.html") == first_report_time);
  const std::string logs = rig.logs();
  INFO(logs);
  CHECK(logs.find("<5>" + dir2.filename().string() + ": report missing") != std::string::npos);
  CHECK(logs.find("<6>" + dir2.filename().string() + ": report: ") != std::string::npos);
  CHECK(logs.find("<5>" + daemon_dir.filename().string() + ": report missing") ==
        std::string::npos);
  rig.daemon->signal(SIGTERM);
  CHECK(rig.daemon->wait(10s));
}

TEST_CASE("displacement: [scan] method = \"both\" is refused at start, naming the key") {
  test::TempDir dir;
  std::string t = test::quick_simulator_config();
  test::replace_once(t, "method = \"four_sensor\"", "method = \"both\"");
  const fs::path cfg = dir / "machine.toml";
  std::ofstream(cfg) << t;
  std::string out;
  const int rc = test::run_command(test::app_path("daemon").string() + " --config " + cfg.string() +
                                       " --results-dir " + (dir / "results").string() +
                                       " --device-port 1 --no-register-map",
                                   &out);
  INFO(out);
  CHECK(rc == 1);
  CHECK_THAT(out,
             Catch::Contains("scan.method: 'both': the daemon runs one kind of scan per trigger"));
}

TEST_CASE(
    "displacement with [refine] enabled and scan 2 backwards: the daemon's folder holds the "
    "loop's account, the drift of sensor 1 identified") {
  test::DaemonRig rig;
  std::string t = test::quick_simulator_config();
  test::replace_once(t, "method = \"four_sensor\"", "method = \"displacement\"");
  test::replace_once(t, "averages = 100", "averages = 5");
  test::replace_once(t, "scan2_order = \"forward\"", "scan2_order = \"backward\"");
  test::replace_once(t, "drift_um_per_s = 0.0", "drift_um_per_s = 0.2");
  t += "\n[report]\npdf = false\n\n[refine]\nenabled = true\n";
  rig.config = rig.tmp / "machine.toml";
  std::ofstream(rig.config) << t;
  rig.devsim.start(rig.config, rig.tmp / "devsim.log");
  rig.start_daemon();
  REQUIRE(rig.notify->wait_for("READY=1", 15s));
  const auto r = rig.trigger_and_wait(1, 60s);
  REQUIRE(r[test::reg_last_outcome] == 1);  // complete
  const auto folder = rig.result_folder(1);
  REQUIRE(folder);
  const fs::path dir = *folder;
  rig.daemon->signal(SIGTERM);
  CHECK(rig.daemon->wait(10s));
  const auto files = files_under(dir);
  for (const char* f :
       {"raw_displacement.csv", "displacement.csv", "refine/displacement_refine.csv",
        "refine/displacement.csv", "report/report.html"}) {
    INFO(f);
    CHECK(files.count(f) == 1);
  }
  CHECK(io::check_result_set(dir).whole());
  CHECK_THAT(test::read_file(dir / "raw_displacement.csv"),
             Catch::Contains("# scan2_order: backward"));
  const auto account =
      io::read_csv(dir / "refine" / "displacement_refine.csv", {.allow_non_finite = true});
  CHECK(account.meta("source") ==
        std::optional<std::string>((dir / "raw_displacement.csv").string()));
  std::string steps;  // the account's steps and notes, so a failure says what was found
  for (const auto& [k, v] : account.metadata)
    if (k.rfind("step", 0) == 0 || k.rfind("note", 0) == 0) steps += k + ": " + v + "\n";
  INFO(steps);
  // devsim drifts linearly in its own time; the readings' recorded times carry the loaded
  // machine's scheduling jitter, and on a scan of a few seconds the first-order thermal drift
  // of the library (one parameter more, counted by AIC) then fits sensor 1's drift as well or
  // better (seen in CI under ASan: "thermal drift of sensor 1 (tau = 0.306 s)", applied, w moved
  // 0.02 um).  Either is the drift of sensor 1; which of the two is not what this test is about.
  const std::string effect = account.meta("step1_effect").value_or("(none)");
  CHECK((effect == "drift of sensor 1" || effect.rfind("thermal drift of sensor 1 (", 0) == 0));
  const auto d = account.meta("step1_decision").value_or("");
  CHECK((d == "applied" || d == "detected, not applied"));
  // The same drift of the reference sensor 2 is suspected and no two scans identify it: the
  // account says what it adds to u(w), and the refined u(w) is wider than the separation's
  // (RMS; at a point it can be below it where a correction was applied, because σ̂ of the
  // repeat then no longer holds the drift).
  bool sensor2 = false;
  for (int i = 1; account.meta("note" + std::to_string(i)); ++i)
    sensor2 =
        sensor2 || account.meta("note" + std::to_string(i))->find("the same effect on sensor 2") !=
                       std::string::npos;
  CHECK(sensor2);
  const auto ub = io::read_csv(dir / "displacement.csv").column("u_w_um");
  const auto ur = io::read_csv(dir / "refine" / "displacement.csv").column("u_w_um");
  REQUIRE(ub.size() == ur.size());
  auto rms = [](const std::vector<double>& v) {
    double s = 0;
    for (const double x : v)
      s += x * x / static_cast<double>(v.size());
    return std::sqrt(s);
  };
  std::printf("daemon, scan 2 backwards, 0.2 um/s drift: u(w) rms %.3g -> %.3g um refined\n",
              rms(ub), rms(ur));
  CHECK(rms(ur) > rms(ub));
  test::check_report_reads(dir);
}

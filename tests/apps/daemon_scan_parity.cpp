// errsep-daemon and errsep-scan on the same simulated machine write the same result folder
// (issue 17, "one result directory"): one errsep-devsim, one machine config with [refine] on;
// the daemon's scan is triggered through its register map (mbpoll on the start coil, as the
// other daemon tests do), errsep-scan scans the same devices.  Both folders must hold the same
// files (raw.csv, motion.csv, reference.csv, lcurve.csv, residuals.csv, summary.txt, refine/, the
// manifest) with the same CSV columns; the daemon's raw file, in its store and in its folder,
// must carry every metadata line errsep-scan's raw file carries (the sampler's counters: missed
// periods, overruns, jitter, the real-time set-up; the store's file all but run_id, which names a
// result set's run), because both scans are acq::run_scan's; both folders hold the report made
// after the scan (report/: the same file names, evaluation.csv and report.html among them, the
// same evaluation.csv columns; issue 17 item 4), the daemon's journal says where it is; and
// errsep-report must read both folders.  The PDF per [report] pdf where Chromium exists, off
// where it does not (the report then says why it has none, in both folders alike).
#include <catch2/catch.hpp>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>

#include "errsep/io/raw_scan_csv.hpp"
#include "support/daemon_rig.hpp"
#include "support/result_files.hpp"

using namespace errsep;
using namespace std::chrono_literals;
using errsep::test::files_under;
using errsep::test::header_of;
namespace fs = std::filesystem;

namespace {

std::set<std::string> metadata_keys(const io::RawFourSensorScan& raw) {
  std::set<std::string> keys;
  for (const auto& kv : raw.metadata)
    keys.insert(kv.first);
  return keys;
}

}  // namespace

TEST_CASE("the daemon and errsep-scan write the same result folder, errsep-report reads both") {
  test::DaemonRig rig;
  rig.devsim.start(rig.config, rig.tmp / "devsim.log");
  // The rig's machine with its buses on this simulator (so errsep-scan talks to it too, instead
  // of starting its own) and the refine step on.
  std::string toml = test::read_file(rig.config);
  test::replace_once(toml, "embedded = true", "embedded = false");
  for (int bus = 0; bus < 2; ++bus)
    test::replace_once(toml, "port = 0\n", "port = " + std::to_string(rig.devsim.port) + "\n");
  toml += "\n[refine]\nenabled = true\n";
  const bool chromium = fs::exists("/usr/bin/chromium");
  // The rig's machine makes no PDF; this test prints one where Chromium exists.
  if (chromium) test::replace_once(toml, "pdf = false", "pdf = true");
  rig.config = rig.tmp / "machine.toml";
  std::ofstream(rig.config) << toml;

  rig.start_daemon();
  REQUIRE(rig.notify->wait_for("READY=1", 15s));
  const auto r = rig.trigger_and_wait(1, 60s);
  REQUIRE(r[test::reg_last_outcome] == 1);  // complete
  const auto store_raw = rig.find_file(1, "raw");
  REQUIRE(store_raw);
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
                            " --out " + scan_dir.string() + " --no-mqtt",
                        &scan_out);
  INFO(scan_out);
  REQUIRE(rc == 0);

  // The same files, refine/ included, each folder a whole result set.
  // The same files, each folder whole, the same columns in every CSV.
  CHECK(test::check_same_result_files(daemon_dir, scan_dir) >= 5);
  const auto daemon_files = files_under(daemon_dir), scan_files = files_under(scan_dir);
  for (const char* f : {"raw.csv", "motion.csv", "reference.csv", "lcurve.csv", "residuals.csv",
                        "summary.txt", "refine/refine_report.txt"})
    CHECK(daemon_files.count(f) == 1);
  // The report after the scan, in both folders: the same file names under report/, the
  // evaluation and the HTML report among them (the PDF too where Chromium printed it).
  const auto under_report = [](const std::set<std::string>& files) {
    std::set<std::string> sub;
    for (const auto& f : files)
      if (f.rfind("report/", 0) == 0) sub.insert(f);
    return sub;
  };
  const auto daemon_report = under_report(daemon_files);
  CHECK(daemon_report == under_report(scan_files));
  for (const char* f : {"report/evaluation.csv", "report/evaluation.txt", "report/report.html"}) {
    INFO(f);
    CHECK(daemon_report.count(f) == 1);
  }
  if (chromium) CHECK(daemon_report.count("report/report.pdf") == 1);
  CHECK(header_of(daemon_dir / "report/evaluation.csv") ==
        header_of(scan_dir / "report/evaluation.csv"));
  CHECK_FALSE(header_of(daemon_dir / "report/evaluation.csv").empty());
  {
    const std::string logs = rig.logs();
    INFO(logs);
    CHECK(logs.find("<6>" + daemon_dir.filename().string() + ": report: ") != std::string::npos);
    CHECK(logs.find("the report failed") == std::string::npos);
  }

  // The daemon's raw file (in its store and in its folder) carries every metadata line of
  // errsep-scan's: the sampler's counters among them.
  const auto scan_raw = io::read_raw_four_sensor_csv(scan_dir / "raw.csv");
  const auto scan_keys = metadata_keys(scan_raw);
  for (const char* k : {"periods", "missed_periods", "overruns", "jitter_us_bus0", "realtime_bus0",
                        "retries", "read_errors", "samples"})
    CHECK(scan_keys.count(k) == 1);
  for (const fs::path& p : {*store_raw, daemon_dir / "raw.csv"}) {
    INFO(p.string());
    const auto raw = io::read_raw_four_sensor_csv(p);
    CHECK(raw.complete);
    const auto keys = metadata_keys(raw);
    for (const auto& k : scan_keys) {
      // run_id names a result set's run: the store's own raw file is in no set.
      if (k == "run_id" && p == *store_raw) continue;
      INFO("metadata key " << k);
      CHECK(keys.count(k) == 1);
    }
    CHECK(raw.metadata.size() == keys.size());  // one line per key
    CHECK(raw.meta("missed_periods"));
    CHECK(raw.meta("outcome") == std::optional<std::string>("complete"));
  }

  // errsep-report reads both.
  for (const fs::path& dir : {daemon_dir, scan_dir}) {
    test::check_report_reads(dir);
    CHECK(fs::exists(dir / "evaluation.csv"));
  }
}

// SIGKILL of errsep-daemon, against the device simulator:
//  - many lives, each killed at a point aimed in turn at: the end of its scan as the register
//    map shows it (every point measured, then 0-50 ms), the end-of-scan writes as inotify shows
//    them (the raw file's temporary created, then 0-3 ms: inside the raw file's write and
//    rename, the checkpoint's removal, the separation, the result's write and rename), a
//    checkpoint's write (its temporary created, then 0-3 ms), a random time of the scan.  After
//    every kill each store file present is whole: a raw file complete with one row per
//    position, a checkpoint marked incomplete with as many readings as it says, a result with
//    one row per position of its raw file, every file ending with its newline -- never
//    truncated or half-written.  The checks are shown to refuse every truncation of such files,
//    and the kills to land in the end-of-scan writes.  A restarted daemon removes the
//    temporaries a killed writer left and the checkpoints a complete raw file superseded, and
//    does not reuse a scan id on disk;
//  - mid-scan: the checkpoint written while the scan ran is on disk, parses, and is marked
//    incomplete (outcome in_progress) with the points measured up to it.
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <stdexcept>
#include <thread>

#include "errsep/io/csv.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "errsep/io/results_store.hpp"
#include "errsep/io/staged_directory.hpp"
#include "support/daemon_rig.hpp"
#include "support/kill_campaign.hpp"

using namespace errsep;
using namespace std::chrono_literals;
using clk = std::chrono::steady_clock;
using test::DaemonRig;

namespace {

bool is_temporary(const std::string& name) {
  return io::temporary_owner_pid(name) >= 0;
}

using test::check_store;
using test::DirWatch;

/// Truncations of `file` that `check` accepts (0 expected): cut at every line boundary and one
/// byte either side of it, at every byte of the last line, and at every 7th byte elsewhere.
template <class Check>
int truncations_accepted(const std::filesystem::path& file, const std::filesystem::path& scratch,
                         Check check, int* tried) {
  std::ifstream in(file, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::filesystem::create_directories(scratch);
  const auto cut = scratch / file.filename();
  const std::size_t last_line = bytes.size() < 2 ? 0 : bytes.rfind('\n', bytes.size() - 2);
  int accepted = 0;
  for (std::size_t k = 0; k < bytes.size(); ++k) {
    const bool boundary = (k > 0 && bytes[k - 1] == '\n') || bytes[k] == '\n' ||
                          (k + 1 < bytes.size() && bytes[k + 1] == '\n');
    if (!boundary && k < last_line && k % 7 != 0) continue;
    ++*tried;
    { std::ofstream(cut, std::ios::binary | std::ios::trunc) << bytes.substr(0, k); }
    if (check(cut).empty()) {
      ++accepted;
      UNSCOPED_INFO(file.filename().string()
                    << " cut at " << k << " of " << bytes.size() << " bytes passes the check");
    }
  }
  return accepted;
}

}  // namespace

TEST_CASE("SIGKILL at the end of scans and mid-scan leaves only whole files") {
  DaemonRig rig;
  // The same machine made quick (stages 10x faster, no settle time, K = 2): more scans, so more
  // kills, in the time budget.  The files are written exactly as with the slow machine.
  {
    std::ifstream in(rig.config);
    std::string cfg((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    for (const auto& [from, to] : std::vector<std::pair<std::string, std::string>>{
             {"speed_mm_s = 400.0", "speed_mm_s = 4000.0"},
             {"\naverages = 5", "\naverages = 2"},
             {"\nsettle_ms = 2", "\nsettle_ms = 0"}}) {
      for (auto p = cfg.find(from); p != std::string::npos; p = cfg.find(from, p + to.size()))
        cfg.replace(p, from.size(), to);
    }
    rig.config = rig.tmp / "machine-fast.toml";
    std::ofstream(rig.config) << cfg;
  }
  rig.devsim.start(rig.config, rig.tmp / "devsim.log");
  const unsigned seed = 20261124;
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> end_delay_ms(0, 50), mid_delay_ms(0, 300);
  std::uniform_int_distribution<int> write_delay_us(0, 3000), checkpoint_n(1, 4);
  // Kinds of kill, in turn:
  //  points:     the register map shows every point measured, then 0-50 ms (files being
  //              written -- or, as often as not, already written: the end phase is ~2 ms);
  //  write:      inotify shows the temporary of the raw file created, then 0-3 ms: inside the
  //              raw file's write, its rename, the checkpoint's removal, the separation, the
  //              result's write and rename;
  //  checkpoint: inotify shows the n-th checkpoint's temporary created, then 0-3 ms;
  //  random:     0-300 ms after the trigger (moving, averaging, checkpoints).
  const char* kinds_of_kill[] = {"points", "write", "checkpoint", "write",
                                 "points", "write", "random",     "write"};
  constexpr int kMinKills = 8, kMaxKills = 60;
  const auto budget = 10s;
  std::map<std::string, std::map<std::string, int>> where;  // kind of kill -> where it landed
  int end_window = 0;  // end-aimed kills that landed before the result file was on disk
  int cut_writes = 0;  // kills between a file's creation and its rename (temporary left)
  const auto t_start = clk::now();
  int k = 0;
  for (; k < kMaxKills && (k < kMinKills || clk::now() - t_start < budget); ++k) {
    // Checkpoints every 50 ms, so that kills meet checkpoint writes too.
    rig.start_daemon({"--checkpoint-ms", "50"});
    REQUIRE(rig.notify->wait_for("READY=1", 15s));
    // The daemon continues after the highest scan id on disk: this life's scan.
    const std::uint64_t id = io::ResultsStore({rig.results, 0, {}}).next_scan_id();
    const std::string kind = kinds_of_kill[k % 8];
    DirWatch watch(rig.results);
    REQUIRE(test::mbpoll_write_coil(rig.modbus_port, 0, 1) == 0);
    long delay = 0;  // us
    if (kind == "points") {
      // As fast as mbpoll answers (~20 ms a read): every point measured, files being written.
      const auto until = clk::now() + 20s;
      std::vector<long> r;
      while (clk::now() < until) {
        r = rig.registers();
        if (r.size() == test::kRegisterCount &&
            ((r[test::reg_state] == 2 && r[test::reg_points_total] > 0 &&
              r[test::reg_points_done] == r[test::reg_points_total]) ||
             (r[test::reg_state] == 1 &&
              static_cast<std::uint64_t>(r[test::reg_last_scan_id]) == (id & 0xFFFF))))
          break;
      }
      REQUIRE(r.size() == test::kRegisterCount);
      delay = 1000L * end_delay_ms(rng);
    } else if (kind == "write") {
      REQUIRE(watch.wait_create(".raw.csv.tmp.", 1, 20s));
      delay = write_delay_us(rng);
    } else if (kind == "checkpoint") {
      // A quick scan may end before its n-th checkpoint: then the raw file's write is the aim.
      REQUIRE(
          watch.wait_create(".raw-incomplete.csv.tmp.", checkpoint_n(rng), 20s, ".raw.csv.tmp."));
      delay = write_delay_us(rng);
    } else {
      delay = 1000L * mid_delay_ms(rng);
    }
    const auto t_kill = clk::now() + std::chrono::microseconds(delay);
    while (clk::now() < t_kill) {
      // spin: sub-millisecond aim
    }
    rig.daemon->signal(SIGKILL);
    REQUIRE(rig.daemon->wait(5s));
    rig.daemon.reset();
    const std::string w = test::landed_in_store(rig.results, id);
    ++where[kind][w];
    if ((kind == "points" || kind == "write") && w != "after the result file") ++end_window;
    if (w.find("temporary left") != std::string::npos) ++cut_writes;
    // Checked after every kill, before a restart cleans anything up.
    std::map<std::string, int> kinds;
    const std::string why = check_store(rig.results, kinds);
    INFO("seed " << seed << ", kill " << k << " (" << kind << ", scan " << id << ", +" << delay
                 << " us): " << w);
    REQUIRE(why == "");
    // A fresh notify socket per life: messages of the killed daemon are not READY of the next.
    rig.notify = std::make_unique<test::NotifyListener>(rig.tmp / ("notify" + std::to_string(k)));
  }
  const double wall_s = std::chrono::duration<double>(clk::now() - t_start).count();

  std::map<std::string, int> kinds;
  REQUIRE(check_store(rig.results, kinds) == "");
  std::string summary;
  for (const auto& [kind, n] : kinds)
    summary += " " + std::to_string(n) + " " + kind + ",";
  std::string hist;
  for (const auto& [kind, h] : where) {
    hist += "\n  " + kind + ":";
    for (const auto& [w, n] : h)
      hist += "\n    " + std::to_string(n) + " x " + w;
  }
  WARN(k << " SIGKILLs in " << wall_s << " s (seed " << seed << "); files:" << summary << "\n  "
         << end_window
         << " kills aimed at the end of a scan landed before its result file was on disk, "
         << cut_writes << " between a file's creation and its rename" << hist);
  // The aim works: kills do land while the files of a scan's end are written, and between
  // writing a file and renaming it.
  CHECK(end_window >= 1);
  CHECK(cut_writes >= 1);
  CHECK(kinds["raw"] >= 1);
  CHECK(kinds["result"] >= 1);
  CHECK(kinds["raw-incomplete"] >= 1);

  // The checks refuse truncations of a result, a raw file and a checkpoint.
  int tried = 0;
  const auto cut_dir = rig.tmp / "cut";
  for (const auto& f : io::ResultsStore({rig.results, 0, {}}).list()) {
    if (f.kind != "result") continue;
    const auto raw_path = rig.find_file(f.scan_id, "raw");
    REQUIRE(raw_path);
    io::RawFourSensorScan raw;
    REQUIRE(test::check_raw_file(*raw_path, &raw) == "");
    CHECK(truncations_accepted(
              f.path, cut_dir,
              [&](const std::filesystem::path& p) { return test::check_result_file(p, raw); },
              &tried) == 0);
    CHECK(truncations_accepted(
              *raw_path, cut_dir,
              [](const std::filesystem::path& p) { return test::check_raw_file(p); }, &tried) == 0);
    break;
  }
  for (const auto& f : io::ResultsStore({rig.results, 0, {}}).list()) {
    if (f.kind != "raw-incomplete") continue;
    CHECK(truncations_accepted(
              f.path, cut_dir,
              [](const std::filesystem::path& p) { return test::check_checkpoint_file(p); },
              &tried) == 0);
    break;
  }
  WARN(tried << " truncations of a result, a raw file and a checkpoint tried");
  CHECK(tried > 300);

  // A restart removes the temporaries and superseded checkpoints and continues the scan ids
  // after those on disk.  A temporary is planted, as a kill inside write_file_atomic leaves one.
  std::set<std::uint64_t> ids;
  for (const auto& f : io::ResultsStore({rig.results, 0, {}}).list())
    ids.insert(f.scan_id);
  REQUIRE_FALSE(ids.empty());
  const auto planted = rig.results / ".20261123T000000Z_scan000999.raw.csv.tmp.Ab12Cd";
  { std::ofstream(planted) << "# format: errsep raw four-sensor scan\n# complete: tr"; }
  // A kill between a complete raw file and its result, made certain: one result removed.
  std::string unresulted;
  for (const auto& f : io::ResultsStore({rig.results, 0, {}}).list())
    if (f.kind == "result") {
      unresulted = f.stem;
      std::filesystem::remove(f.path);
      break;
    }
  REQUIRE_FALSE(unresulted.empty());
  // A result that is not of its raw file (its raw_crc32 differs): made again from the raw file.
  std::string foreign;
  for (const auto& f : io::ResultsStore({rig.results, 0, {}}).list())
    if (f.kind == "result") {
      io::CsvTable t = io::read_csv(f.path);
      REQUIRE(t.meta("raw_crc32"));
      t.set_meta("raw_crc32", "00000000");
      io::write_csv(f.path, t);
      foreign = f.stem;
      break;
    }
  REQUIRE_FALSE(foreign.empty());
  rig.start_daemon();
  REQUIRE(rig.notify->wait_for("READY=1", 15s));
  std::set<std::string> raw_stems, result_stems;
  for (const auto& f : io::ResultsStore({rig.results, 0, {}}).list()) {
    if (f.kind == "raw") raw_stems.insert(f.stem);
    if (f.kind == "result") result_stems.insert(f.stem);
  }
  for (const auto& e : std::filesystem::directory_iterator(rig.results)) {
    const std::string name = e.path().filename().string();
    INFO(name);
    CHECK_FALSE(is_temporary(name));
    const auto f = io::parse_store_name(e.path());
    if (f && f->kind == "raw-incomplete") CHECK(raw_stems.count(f->stem) == 0);
  }
  CHECK_FALSE(std::filesystem::exists(planted));
  // Every complete raw file has its result again (made at the start from the raw file), whole.
  for (const auto& stem : raw_stems) {
    INFO(stem);
    REQUIRE(result_stems.count(stem) == 1);
    io::RawFourSensorScan raw;
    REQUIRE(test::check_raw_file(rig.results / (stem + ".raw.csv"), &raw) == "");
    CHECK(test::check_result_file(rig.results / (stem + ".result.csv"), raw) == "");
  }
  CHECK(result_stems.count(unresulted) == 1);
  // The result set to another raw file's CRC was made again from its own raw file.
  {
    char hex[16];
    std::snprintf(hex, sizeof hex, "%08x",
                  io::file_size_and_crc32(rig.results / (foreign + ".raw.csv")).second);
    CHECK(io::read_csv(rig.results / (foreign + ".result.csv")).meta("raw_crc32") ==
          std::optional<std::string>(hex));
  }
  std::map<std::string, int> kinds_after;
  CHECK(check_store(rig.results, kinds_after) == "");
  REQUIRE(test::mbpoll_write_coil(rig.modbus_port, 0, 1) == 0);
  // The quick machine may finish the scan between two reads: its id is then the last scan id.
  const auto r = rig.wait_regs(
      [](const std::vector<long>& x) {
        return x[test::reg_scan_id] > 0 || x[test::reg_last_scan_id] > 0;
      },
      20s);
  REQUIRE(r.size() == test::kRegisterCount);
  const auto new_id = static_cast<std::uint64_t>(
      r[test::reg_scan_id] > 0 ? r[test::reg_scan_id] : r[test::reg_last_scan_id]);
  CHECK(ids.count(new_id) == 0);
  CHECK(new_id > *ids.rbegin());
}

TEST_CASE("SIGKILL mid-scan: the checkpoint is on disk, parses and is marked incomplete") {
  DaemonRig rig;
  rig.devsim.start(rig.config, rig.tmp / "devsim.log");
  rig.start_daemon({"--checkpoint-ms", "200"});
  REQUIRE(rig.notify->wait_for("READY=1", 15s));
  REQUIRE(test::mbpoll_write_coil(rig.modbus_port, 0, 1) == 0);
  // Wait for a checkpoint with some points, while the scan is still far from its end.
  std::optional<std::filesystem::path> cp;
  auto r = rig.wait_regs(
      [&](const std::vector<long>& x) {
        cp = rig.find_file(1, "raw-incomplete");
        return cp && x[test::reg_state] == 2 && x[test::reg_points_done] >= 8;
      },
      20s);
  REQUIRE(cp);
  REQUIRE(r[test::reg_state] == 2);
  const auto total = static_cast<std::size_t>(r[test::reg_points_total]);
  REQUIRE(static_cast<std::size_t>(r[test::reg_points_done]) < total);
  rig.daemon->signal(SIGKILL);
  REQUIRE(rig.daemon->wait(5s));
  const auto done_at_kill = static_cast<std::size_t>(r[test::reg_points_done]);

  CHECK_FALSE(rig.find_file(1, "raw"));
  CHECK_FALSE(rig.find_file(1, "result"));
  cp = rig.find_file(1, "raw-incomplete");
  REQUIRE(cp);
  // Refused as a scan to separate, readable as an incomplete one.
  CHECK_THROWS_AS(io::read_raw_four_sensor_csv(*cp), io::CsvError);
  io::RawFourSensorScan scan;
  REQUIRE(test::check_checkpoint_file(*cp, &scan) == "");
  CHECK_FALSE(scan.complete);
  CHECK(scan.meta("outcome") == std::optional<std::string>("in_progress"));
  CHECK(scan.meta("scan_id") == std::optional<std::string>("1"));
  CHECK(scan.meta("checkpoint_utc"));
  std::size_t measured = 0;
  for (const auto& col : scan.m_um)
    for (double v : col)
      measured += std::isfinite(v) ? 1 : 0;
  WARN("checkpoint after SIGKILL: " << measured << " of " << total << " points ("
                                    << *scan.meta("points_measured") << "); " << done_at_kill
                                    << "+ measured when the kill was sent");
  CHECK(measured >= 1);
  CHECK(measured < total);
  CHECK(4 * scan.positions() == total);
  // Configuration 1 is measured first, position by position: the checkpoint holds a prefix.
  std::size_t k = 0;
  bool prefix = true;
  for (std::size_t i = 0; i < 4; ++i)
    for (std::size_t n = 0; n < scan.positions(); ++n, ++k)
      prefix = prefix && (std::isfinite(scan.m_um[i][n]) == (k < measured));
  CHECK(prefix);

  // A restart keeps it (no complete raw file supersedes it) and does not reuse its scan id.
  rig.notify = std::make_unique<test::NotifyListener>(rig.tmp / "notify2");
  rig.start_daemon();
  REQUIRE(rig.notify->wait_for("READY=1", 15s));
  CHECK(std::filesystem::exists(*cp));
  REQUIRE(test::mbpoll_write_coil(rig.modbus_port, 0, 1) == 0);
  r = rig.wait_regs([](const std::vector<long>& x) { return x[test::reg_state] == 2; }, 20s);
  REQUIRE(r.size() == test::kRegisterCount);
  CHECK(r[test::reg_scan_id] == 2);
}

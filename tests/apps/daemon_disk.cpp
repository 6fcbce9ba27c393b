// errsep-daemon with a full disk (a free-space reserve larger than the disk stands in for it):
// the scan runs, its outcome in the register map is "write failed", the journal says "disk full"
// once per file that could not be written (checkpoints included, without repeating itself every
// checkpoint period), STATUS= says so, the daemon keeps running and answering (a trigger is
// accepted, SIGTERM still stops it cleanly), and the results directory holds no partial or
// temporary file.
// A real full file system too (ENOSPC from the kernel): the results directory on a tmpfs with
// room for one file, mounted in a mount namespace of the daemon's own (unshare; skipped with a
// message where namespaces are not available): the first checkpoint is written, the next ones
// and the raw file fail with ENOSPC, reported as disk full, and the last checkpoint stays, whole,
// as the scan's raw data.
#include <signal.h>
#include <sys/wait.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <fstream>
#include <iostream>
#include <sstream>

#include "errsep/io/results_store.hpp"
#include "support/daemon_rig.hpp"

using namespace errsep;
using namespace std::chrono_literals;
using test::DaemonRig;

namespace {
std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}
std::size_t count(const std::string& s, const std::string& needle) {
  std::size_t n = 0;
  for (auto p = s.find(needle); p != std::string::npos; p = s.find(needle, p + 1))
    ++n;
  return n;
}
std::vector<std::string> dir_entries(const std::filesystem::path& dir) {
  std::vector<std::string> v;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    v.push_back(e.path().filename().string());
  return v;
}
}  // namespace

TEST_CASE("disk full: write_failed in the register map, a clear journal line, no partial file") {
  DaemonRig rig;
  rig.devsim.start(rig.config, rig.tmp / "devsim.log");
  // 10^9 MiB of reserve: more than any disk has free.
  rig.start_daemon({"--min-free-mb", "1e9", "--checkpoint-ms", "100"});
  REQUIRE(rig.notify->wait_for("READY=1", 15s));

  auto r = rig.trigger_and_wait(1, 20s);
  CHECK(r[test::reg_last_outcome] == 5);  // write failed
  CHECK(r[test::reg_scans_completed] == 0);
  CHECK(r[test::reg_state] == 1);  // idle: a full disk is not a device fault
  CHECK(rig.notify->wait_for("STATUS=idle: last scan 1 write_failed (disk full)", 2s));
  CHECK(rig.daemon->running());

  const std::string log = slurp(rig.tmp / "daemon.log");
  INFO(log);
  // The scan's raw file: one error line naming the file and the cause.
  CHECK(count(log, "<3>scan 1: disk full, results not written: cannot write '") == 1);
  CHECK(log.find(".raw.csv': disk full: ") != std::string::npos);
  // Checkpoints failed every 100 ms for the whole scan: said once, not every time.
  CHECK(count(log, "scan 1: checkpoint not written: ") == 1);
  CHECK(log.find("raw-incomplete.csv': disk full") != std::string::npos);
  // Nothing on disk: no partial file, no temporary, no checkpoint.
  const auto files = dir_entries(rig.results);
  INFO(files.size() << " files in the results directory");
  CHECK(files.empty());

  // Still running and answering: the next trigger is accepted, and SIGTERM during that scan
  // stops the daemon cleanly although the incomplete raw data cannot be written either.
  REQUIRE(test::mbpoll_write_coil(rig.modbus_port, 0, 1) == 0);
  r = rig.wait_regs(
      [](const std::vector<long>& x) {
        return x[test::reg_state] == 2 && x[test::reg_scan_id] == 2 &&
               x[test::reg_points_done] >= 3;
      },
      20s);
  REQUIRE(r.size() == test::kRegisterCount);
  REQUIRE(r[test::reg_state] == 2);
  rig.daemon->signal(SIGTERM);
  const auto st = rig.daemon->wait(10s);
  REQUIRE(st);
  CHECK(WIFEXITED(*st));
  CHECK(WEXITSTATUS(*st) == 0);
  const std::string log2 = slurp(rig.tmp / "daemon.log");
  CHECK(count(log2, "<3>scan 2: disk full, results not written: cannot write '") == 1);
  CHECK(log2.find("raw-incomplete.csv': disk full: ") != std::string::npos);
  CHECK(dir_entries(rig.results).empty());
}

TEST_CASE("disk full for real: ENOSPC on a tmpfs, reported, the last checkpoint kept whole") {
  DaemonRig rig;
  std::filesystem::create_directories(rig.results);
  // Can this process mount in a namespace of its own?  (Root, or unprivileged user namespaces.)
  std::string out;
  const auto probe = rig.tmp / "probe";
  std::filesystem::create_directories(probe);
  if (test::run_command("/usr/bin/unshare -Urm sh -c 'mount -t tmpfs -o size=64k tmpfs " +
                            probe.string() + "' 2>&1",
                        &out) != 0) {
    std::cout << "SKIPPED: cannot mount a tmpfs in a user+mount namespace (unshare -Urm): " << out
              << "\n";
    return;
  }
  rig.devsim.start(rig.config, rig.tmp / "devsim.log");
  // Room for the directory and one file (nr_inodes = 2): the first checkpoint is created, any
  // further file is ENOSPC.
  rig.prefix = {"/usr/bin/unshare",
                "-Urm",
                "sh",
                "-c",
                "mount -t tmpfs -o size=1m,nr_inodes=2 tmpfs \"$0\" && exec \"$@\"",
                rig.results.string()};
  rig.start_daemon({"--min-free-mb", "0", "--checkpoint-ms", "100"});
  REQUIRE(rig.notify->wait_for("READY=1", 15s));
  // The daemon's view of its results directory (the tmpfs exists in its namespace only).
  const auto dir = std::filesystem::path("/proc") / std::to_string(rig.daemon->pid()) / "root" /
                   rig.results.relative_path();

  auto r = rig.trigger_and_wait(1, 20s);
  CHECK(r[test::reg_last_outcome] == 5);  // write failed
  CHECK(r[test::reg_state] == 1);
  CHECK(rig.notify->wait_for("STATUS=idle: last scan 1 write_failed (disk full)", 2s));
  REQUIRE(rig.daemon->running());

  const std::string log = slurp(rig.tmp / "daemon.log");
  INFO(log);
  CHECK(count(log, "scan 1: checkpoint not written: ") == 1);
  CHECK(count(log, "<3>scan 1: disk full, results not written: cannot write '") == 1);
  CHECK(log.find(".raw.csv': create temporary file: disk full (ENOSPC)") != std::string::npos);
  CHECK(log.find("its last checkpoint (") != std::string::npos);

  // Left: the first checkpoint, whole, and nothing else.
  const auto files = dir_entries(dir);
  REQUIRE(files.size() == 1);
  const auto f = io::parse_store_name(files.front());
  REQUIRE(f);
  CHECK(f->scan_id == 1);
  CHECK(f->kind == "raw-incomplete");
  io::RawFourSensorScan cp;
  REQUIRE(test::check_checkpoint_file(dir / files.front(), &cp) == "");
  CHECK(cp.meta("outcome") == std::optional<std::string>("in_progress"));
  WARN("ENOSPC: the checkpoint kept holds " << *cp.meta("points_measured") << " points");

  rig.daemon->signal(SIGTERM);
  const auto st = rig.daemon->wait(10s);
  REQUIRE(st);
  CHECK(WIFEXITED(*st));
  CHECK(WEXITSTATUS(*st) == 0);
}

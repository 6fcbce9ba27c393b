// errsep-daemon with a full disk (a free-space reserve larger than the disk stands in for it):
// the scan runs, its outcome in the register map is "write failed", the journal says "disk full"
// once per file that could not be written (checkpoints included, without repeating itself every
// checkpoint period), STATUS= says so, the daemon keeps running and answering (a trigger is
// accepted, SIGTERM still stops it cleanly), and the results directory holds no partial or
// temporary file.
#include <signal.h>
#include <sys/wait.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <fstream>
#include <sstream>

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

  REQUIRE(test::mbpoll_write_coil(rig.modbus_port, 0, 1) == 0);
  auto r = rig.wait_regs(
      [](const std::vector<long>& x) {
        return x[test::reg_last_scan_id] == 1 && x[test::reg_state] == 1;
      },
      20s);
  REQUIRE(r.size() == test::kRegisterCount);
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

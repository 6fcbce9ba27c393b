// Issue 21: a scan killed at any moment leaves nothing that misleads and nothing running.
// SIGKILLs of errsep-scan (into a fresh --out folder and into one holding an earlier result;
// at random moments, into the end-of-scan writes and at the commit) and of errsep-daemon (during
// scans triggered through its start coil; random and at the raw file's write), each followed by
// checks of what a reader finds and of what the next run does (support/kill_campaign.hpp).
// Asserted: 0 torn files, 0 result folders with files of two runs, 0 result folders with only
// some result files that a reader accepts, 0 errsep processes left running, 0 temporaries of a
// killed run left after the next run, 0 failed next runs, nothing reported written then missing.
//
// The campaign of issue 21's note (1000 kills by default, ERRSEP_KILLS to change it; about 10
// minutes on the 2-core VM) is the hidden case:
//   ERRSEP_KILLS=1000 build/tests/test_apps_kill "[.campaign]"
#include <catch2/catch.hpp>
#include <cstdlib>
#include <iostream>

#include "support/kill_campaign.hpp"

using namespace errsep;

namespace {

void report(const test::KillCounts& k) {
  std::cout << k.table();
  for (const auto& f : k.failures)
    std::cout << "  - " << f << "\n";
  std::cout.flush();
}

}  // namespace

TEST_CASE("about 50 SIGKILLs of errsep-scan and errsep-daemon leave nothing that misleads") {
  test::KillCampaignOptions o;  // 32 kills of errsep-scan, 16 of the daemon, within ~50 s
  const test::KillCounts k = test::run_kill_campaign(o);
  report(k);
  INFO(k.table());
  // The campaign did what it says: both programs, both lanes, kills into the writes.
  CHECK(k.scan_kills >= 8);
  CHECK(k.scan_fresh >= 3);
  CHECK(k.scan_overwritten >= 3);
  CHECK(k.scan_landed_writing >= 3);
  CHECK(k.daemon_kills >= 8);
  CHECK(k.daemon_aimed_write >= 3);
  // The zeros of issue 21.
  CHECK(k.torn == 0);
  CHECK(k.reported_missing == 0);
  CHECK(k.next_run_failed == 0);
  CHECK(k.daemon_not_recovered == 0);
  CHECK(k.children_left == 0);
  CHECK(k.partial_accepted == 0);
  CHECK(k.mixed == 0);
  CHECK(k.temporaries_left == 0);
}

TEST_CASE("the kill campaign of issue 21 (hidden: ERRSEP_KILLS kills, 1000 by default)",
          "[.campaign]") {
  int kills = 1000;
  if (const char* e = std::getenv("ERRSEP_KILLS")) kills = std::max(2, std::atoi(e));
  test::KillCampaignOptions o;
  // The proportions of issue 21's table: 534 of errsep-scan, 466 of the daemon.
  o.scan_kills = kills * 534 / 1000;
  o.daemon_kills = kills - o.scan_kills;
  o.budget = std::chrono::hours(24);
  const test::KillCounts k = test::run_kill_campaign(o);
  report(k);
  CHECK(k.zeros_broken() == 0);
}

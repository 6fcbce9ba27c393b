#pragma once
// SIGKILLs of errsep-scan and errsep-daemon at random moments and aimed at their end-of-scan
// writes, and what each kill left, counted as in issue 21's table.  Used by the kill ctest
// (~50 kills) and by its hidden campaign case (1000 kills, ERRSEP_KILLS):
//
//   build/tests/test_apps_kill "[.campaign]"            # ERRSEP_KILLS=1000 by default
//
// errsep-scan runs on the embedded device simulator, in two lanes: into a fresh --out folder
// (removed by the test after each check, its parent kept: the next run sweeps the parent) and
// into one that holds the previous run's result set.  Kills are aimed in turn: at a random
// moment of the run, into the end-of-scan writes (the raw file's temporary created in the
// staging folder, then 0..W ms, W the end phase of an unkilled run), and at the commit (the
// manifest's temporary created, then 0-2 ms).  The daemon runs on the DaemonRig; kills: random
// moment of a scan triggered through the start coil, or the raw file's temporary created then
// 0-3 ms; each restart is the next life's start.
#include <sys/types.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "errsep/io/raw_scan_csv.hpp"

namespace errsep::test {

/// inotify on a folder: the moment a file is created in it.
class DirWatch {
 public:
  explicit DirWatch(const std::filesystem::path& dir);
  ~DirWatch();
  DirWatch(const DirWatch&) = delete;
  DirWatch& operator=(const DirWatch&) = delete;
  /// Waits for the n-th file created whose name contains `needle` (or the first containing
  /// `or_needle`, when given); false at the timeout.
  bool wait_create(const std::string& needle, int n, std::chrono::milliseconds timeout,
                   const std::string& or_needle = {});

 private:
  int fd_;
};

/// Checks every file of the daemon's results directory ("" = all whole, each result of its raw
/// file); counts them by kind ("temporary" for a killed writer's temporaries).
std::string check_store(const std::filesystem::path& dir, std::map<std::string, int>& kinds);

/// Where a kill of the daemon landed, from the files of scan `id`.
std::string landed_in_store(const std::filesystem::path& dir, std::uint64_t id);

/// Processes (not zombies) whose command line contains every one of `needles`.
std::vector<pid_t> processes_with(const std::vector<std::string>& needles);

/// What a result folder written by errsep-scan holds, as a reader sees it.
struct FolderVerdict {
  bool present = false;
  bool torn = false;              ///< a file cut, unparsable, or differing from its manifest
  bool mixed = false;             ///< files of two runs (run_id of a file != the set's)
  bool partial_accepted = false;  ///< raw.csv complete with only some result files, set whole
  std::string run_id;             ///< the set's
  std::string why;                ///< what was wrong
};
/// `refine`: a complete scan's set also holds refine/.
FolderVerdict inspect_scan_folder(const std::filesystem::path& out, bool refine);

/// The counts of issue 21's table.
struct KillCounts {
  int scan_kills = 0, scan_fresh = 0, scan_overwritten = 0, daemon_kills = 0;
  int scan_aimed_write = 0, scan_aimed_commit = 0, daemon_aimed_write = 0;
  int scan_landed_writing = 0;  ///< kills of errsep-scan after its raw file's write began
  int torn = 0;                 ///< torn or half-written files
  int reported_missing = 0;     ///< a file reported as written, then missing (or not whole)
  int next_run_failed = 0;
  int daemon_not_recovered = 0;  ///< restart left a killed life's temporary or an unresulted raw
  int children_left = 0;         ///< errsep-devsim of a killed errsep-scan still running
  int partial_accepted = 0;      ///< raw.csv + only some result files, and a reader accepts it
  int mixed = 0;                 ///< a result folder (or a daemon result) of two runs
  int temporaries_left = 0;      ///< a killed run's temporaries still there after the next run
  int unkilled_runs = 0;         ///< runs that ended before their kill (or the final ones)
  std::vector<std::string> failures;  ///< the first few, described
  std::string table() const;          ///< the counts as issue 21's table
  int zeros_broken() const;           ///< sum of the counts that must be 0
};

struct KillCampaignOptions {
  int scan_kills = 32;    ///< kills of errsep-scan (runs that end before their kill do not count)
  int daemon_kills = 16;  ///< kills of errsep-daemon (one per life)
  unsigned seed = 20261125;
  bool refine = true;               ///< errsep-scan --refine in the overwritten lane
  std::chrono::seconds budget{48};  ///< stop starting kills after this (at least 8 of each)
};

/// Runs the campaign; throws std::runtime_error when the set-up itself fails (an app missing, the
/// simulator not starting).
KillCounts run_kill_campaign(const KillCampaignOptions& opts);

}  // namespace errsep::test

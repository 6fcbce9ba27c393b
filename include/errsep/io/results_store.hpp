#pragma once
// The results directory of the scan daemon (under systemd: StateDirectory=errsep, i.e.
// /var/lib/errsep/results).  Every file of a scan is named
//
//   <UTC time>_scan<id>.<kind>.csv        e.g. 20261123T084307Z_scan000042.raw.csv
//
// so that a directory listing sorts by time and a name says which scan it belongs to.  Kinds:
//   raw            the raw scan, "# complete: true"
//   raw-incomplete the raw data of an interrupted/failed scan, "# complete: false", NaN where not
//                  measured; the different name keeps it out of tools that glob *.raw.csv.  The
//                  daemon also writes it as a checkpoint while a scan runs (replaced atomically
//                  by each newer checkpoint, by the final raw-incomplete file, or removed once the
//                  complete raw file is on disk), so a SIGKILL or power cut mid-scan leaves the
//                  points measured up to the last checkpoint
//   result         the separated profiles and the scan's figures (straightness, the raw file's
//                  CRC-32): the store's index of the scan, written last
// and beside them the scan's result folder <stem>/, the same set as errsep-scan's --out folder
// (service/four_sensor_pipeline.hpp; raw.csv, motion.csv, ..., summary.txt), made visible whole
// in one rename before the result file is written; retention removes it with the scan's files.
// Every file is written with write_file_atomic (temp file, fsync, rename, directory fsync): a
// power cut or SIGKILL leaves the whole file or none.  Stray temporary files of a killed writer
// (".<name>.tmp.<pid>.XXXXXX") are removed by clean_stale_temporaries() at start, and a checkpoint
// whose complete raw file made it to disk (a kill between the two) by remove_superseded().
//
// The disk filling up is a DiskFullError (a std::runtime_error that says so and names the file),
// raised before anything is written when the free space is below min_free_bytes, or from the
// write itself (ENOSPC/EDQUOT); never a crash or a partial file.  Old results are deleted only
// when a retention setting is given (keep_scans or max_age_days > 0); the default keeps all.
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace errsep::io {

/// The disk (or quota) is full: nothing was written.
class DiskFullError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct RetentionOptions {
  int keep_scans = 0;       ///< keep the newest N scans (all their files); 0 = no count limit
  double max_age_days = 0;  ///< delete scans older than this; 0 = no age limit
  bool enabled() const noexcept { return keep_scans > 0 || max_age_days > 0; }
  bool is_valid(std::string* why = nullptr) const;
};

struct ResultsStoreOptions {
  std::filesystem::path dir = "results";
  /// Refuse to write (DiskFullError) when fewer bytes than this plus the file's size are free.
  std::uint64_t min_free_bytes = 1u << 20;
  RetentionOptions retention;
  bool is_valid(std::string* why = nullptr) const;
};

/// One file of the store, decoded from its name.
struct StoredFile {
  std::filesystem::path path;
  std::string stem;  ///< "<UTC time>_scan<id>"
  std::uint64_t scan_id = 0;
  std::string kind;  ///< "raw", "raw-incomplete", "result", ...
  std::chrono::system_clock::time_point time;
};

/// 2024-01-01 UTC: no scan of this software is older; a scan time or clock before it is wrong
/// (a board without a battery-backed clock starts in 1970) and retention does not age by it.
std::chrono::system_clock::time_point earliest_plausible_scan_time();

class ResultsStore {
 public:
  /// Creates the directory if needed.  Throws std::runtime_error (naming the directory) when it
  /// cannot be created or is not writable, std::invalid_argument for invalid options.
  explicit ResultsStore(ResultsStoreOptions opts);

  const std::filesystem::path& dir() const noexcept { return opts_.dir; }
  const ResultsStoreOptions& options() const noexcept { return opts_; }

  /// "<YYYYmmddTHHMMSSZ>_scan<id, 6+ digits>" for a scan started at `t`.
  static std::string stem(std::chrono::system_clock::time_point t, std::uint64_t scan_id);
  /// Path of a file of the scan: dir/<stem>.<kind>.csv.
  std::filesystem::path path(std::string_view stem, std::string_view kind) const;

  /// Writes `content` atomically as dir/<stem>.<kind>.csv and returns the path.  Throws
  /// DiskFullError when space is short (nothing written), std::runtime_error for other errors.
  std::filesystem::path write(std::string_view stem, std::string_view kind,
                              std::string_view content);

  /// Removes dir/<stem>.<kind>.csv durably (unlink, directory fsync).  False when there was no
  /// such file; throws std::runtime_error when it exists and cannot be removed.
  bool remove(std::string_view stem, std::string_view kind);

  /// Every file named like a store file, oldest first (by name).
  std::vector<StoredFile> list() const;
  /// One more than the highest scan id present (1 for an empty store), so ids never repeat
  /// across restarts.
  std::uint64_t next_scan_id() const;
  /// Removes temporary files left by a killed writer (io/staged_directory.hpp:
  /// remove_stale_temporaries, with those of older versions that carry no pid).  Returns how many.
  int clean_stale_temporaries();
  /// Removes every raw-incomplete file (a checkpoint) of a scan whose complete raw file is
  /// present: the daemon was stopped between writing the one and removing the other.  Returns
  /// how many.
  int remove_superseded();
  /// Applies the retention setting (no-op when not enabled): removes every file of the scans
  /// beyond the newest keep_scans (newest = highest scan id, whatever the clock said), and of the
  /// scans started before now − max_age_days.  A scan's start is taken as the latest time named
  /// by it or any scan of a lower id; where that time or `now` is before
  /// earliest_plausible_scan_time() or the scan's time is after `now` (a board without a
  /// battery-backed clock before NTP), the age rule keeps the scan.  Returns the number of files
  /// deleted.
  int prune(std::chrono::system_clock::time_point now);

  /// Free bytes for unprivileged writers on the store's file system.
  std::uint64_t free_bytes() const;

 private:
  ResultsStoreOptions opts_;
};

/// Parses a store file name ("<stem>.<kind>.csv"); nullopt when it is not one.
std::optional<StoredFile> parse_store_name(const std::filesystem::path& file);

}  // namespace errsep::io

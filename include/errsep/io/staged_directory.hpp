#pragma once
// A result set: the files one run writes into one folder, made visible whole or not at all, and
// checked whole by whoever reads them.
//
//   <parent>/.<name>.<tag>-partial-<pid>/   the staging folder, beside the target, while writing
//   <parent>/<name>/                        the set, once committed
//   <parent>/<name>/errsep-manifest.txt     written last into the staging folder: the set's kind,
//                                           the run id, the writer, and every file with its size
//                                           and CRC-32 (a sub-folder that is a set of its own, e.g.
//                                           refine/, is listed as such and checked on its own)
//
// commit() moves the staging folder into place in one rename (no earlier set) or one exchange
// (renameat2 RENAME_EXCHANGE with an earlier set), then removes the earlier set, which the
// exchange left at the staging name: the earlier set is not kept.  A reader therefore sees the
// earlier set or the new one, never files of both.  A writer killed at any moment leaves the
// earlier set (or nothing) at the target and its staging folder, named with its pid; the next
// writer into the same folder removes what a dead process left (remove_stale_temporaries).
//
// A writer replaces only a set of its own kind (errsep-scan a scan, errsep-refine a refine
// result, ...), or an empty or absent folder: a folder that holds anything else (a set of another
// kind, say the scan whose raw file errsep-refine is reading, or files errsep did not write) is
// refused before anything runs, never replaced.  A writer that adds to a set (errsep-report: the
// evaluation, figures, report and tables) starts from the set's files (hard links, see
// StageOptions::extend) and commits the whole set anew in the same way.
//
// Readers: check_result_set() / require_whole_result_set() refuse a set that is not whole and say
// what is missing or differs.  A folder without a manifest was not written by this version of
// errsep (by hand, or by an older one): it cannot be checked, and readers say so.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace errsep::io {

/// Name of the manifest inside a set.
inline constexpr const char* kManifestName = "errsep-manifest.txt";

struct StageOptions {
  /// The set's kind and the staging folder's tag ("scan", "refine", "separate", ...).
  std::string kind = "result";
  /// Program and version that writes the set, for the manifest ("errsep-scan 0.1.0").
  std::string writer;
  /// Start from the files of the set (or manifest-less result folder) at the target, linked into
  /// the staging folder, and keep its kind: for writers that add files to a set.  The target must
  /// exist.  Top-level names in `replace` are not taken over (the writer makes them anew).
  bool extend = false;
  std::vector<std::string> replace;
};

class StagedDirectory {
 public:
  /// Removes what dead errsep processes left in the target's parent folder and in the target
  /// (remove_stale_temporaries; see swept()), checks that the target may be replaced (absent,
  /// empty, or a set of the same kind; with `extend`: present), and creates the staging folder
  /// "<parent>/.<name>.<kind>-partial-<pid>".  Throws std::runtime_error naming the target when it
  /// may not be replaced, std::filesystem::filesystem_error for I/O errors.  Not real-time safe.
  explicit StagedDirectory(const std::filesystem::path& out, StageOptions opts);
  explicit StagedDirectory(const std::filesystem::path& out, const std::string& kind = "result");
  StagedDirectory(const StagedDirectory&) = delete;
  StagedDirectory& operator=(const StagedDirectory&) = delete;
  /// Removes the staging folder (after an error: no partial result; the target is untouched).
  ~StagedDirectory();

  /// Where to write the files.
  const std::filesystem::path& dir() const { return dir_; }
  /// The final folder.
  const std::filesystem::path& target() const { return out_; }
  /// "<UTC yyyymmddThhmmssZ>-<pid>-<4 hex digits>": the set's run id in the manifest (with
  /// `extend`, the set keeps its own and this run is listed as one that extended it); writers put
  /// it in their files' metadata too ("# run_id:"), so that a file can be traced to its run.
  const std::string& run_id() const { return run_id_; }
  /// Temporaries of dead errsep processes removed by the constructor.
  const std::vector<std::filesystem::path>& swept() const { return swept_; }

  /// Writes the manifest, moves the set into place (see the header comment) and returns the paths
  /// of its files in the target (the manifest last).  Throws std::runtime_error on I/O errors
  /// (the target then holds the earlier set).  Call at most once.
  std::vector<std::filesystem::path> commit();

 private:
  std::filesystem::path out_, dir_;
  StageOptions opts_;
  std::string run_id_;
  struct ExtendedFrom {  // extend: the set's own identity, kept
    std::string kind, run_id, writer, created_utc;
    std::vector<std::string> extended;
  };
  std::unique_ptr<ExtendedFrom> base_;
  std::vector<std::filesystem::path> swept_;
  bool committed_ = false;
};

/// What a reader found in a result folder.
struct ResultSetCheck {
  bool has_manifest = false;
  std::string kind, run_id, writer;   ///< of the run that wrote the set's data
  std::vector<std::string> run_ids;   ///< run_id, then the runs that extended the set
  std::vector<std::string> files;     ///< relative paths the manifest lists (nested sets: "dir/")
  std::vector<std::string> problems;  ///< each names a file and what is wrong with it
  /// Files in the folder that the manifest does not list: added after the run (by hand, or a
  /// tool that is not errsep).  They do not make the set incomplete; readers that use them say so.
  std::vector<std::string> extra;
  bool whole() const { return has_manifest && problems.empty(); }
};

/// Reads the manifest of `dir` and checks every file it lists (present, size, CRC-32) and every
/// nested set (recursively), and lists what else the folder holds (files starting with '.' are
/// passed over: they are temporaries, not results).  Never throws for what it finds; throws
/// std::filesystem::filesystem_error only when `dir` cannot be listed.
ResultSetCheck check_result_set(const std::filesystem::path& dir);

/// Throws std::runtime_error "<dir>/: not a whole result set: <problems>" unless the folder holds
/// a whole set; a folder without a manifest passes (returns false: not checked), one with a
/// manifest returns true when whole.
bool require_whole_result_set(const std::filesystem::path& dir);

/// require_whole_result_set() on the folder of `file` when that folder holds a manifest: a reader
/// of one file of a set (a raw scan in a scan's result folder) refuses it when its set is not
/// whole.
void require_whole_set_of(const std::filesystem::path& file);

/// The file-name patterns of errsep's own temporaries, with the pid of the process that made them:
///   .<name>.tmp.<pid>.XXXXXX        write_file_atomic (legacy: .<name>.tmp.XXXXXX, pid 0)
///   .<name>.<kind>-partial-<pid>    StagedDirectory
/// Returns the pid, or -1 when `name` is not one of them.
long temporary_owner_pid(const std::string& name);

/// Removes from `dir` (not recursively) the temporaries above whose process is gone: not running,
/// or started after the temporary was made (a reused pid is detected by the boot time only; while
/// such a process runs, its namesake's temporary is kept).  Legacy temporaries without a pid are
/// left alone unless `legacy_too` (the daemon's results directory, where the daemon is the only
/// writer).  Never removes anything else.  Returns what it removed.
std::vector<std::filesystem::path> remove_stale_temporaries(const std::filesystem::path& dir,
                                                            bool legacy_too = false);

/// One line for the user: "removed 2 temporaries left by an interrupted errsep run: a, b"; ""
/// when nothing was removed.
std::string describe_swept(const std::vector<std::filesystem::path>& removed);

/// For writers of single files (write_file_atomic, not a set): remove_stale_temporaries() in the
/// folder of each of `files` (each folder once, empty paths skipped); returns describe_swept().
std::string sweep_beside(const std::vector<std::filesystem::path>& files);

/// CRC-32 (IEEE 802.3, as zlib) and size of a file.  Throws std::runtime_error when unreadable.
std::pair<std::uintmax_t, std::uint32_t> file_size_and_crc32(const std::filesystem::path& file);

}  // namespace errsep::io

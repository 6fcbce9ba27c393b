#pragma once
// A set of result files that appears whole or not at all: the files are written into a staging
// directory beside the output directory, and commit() moves them in only when all are written.
// On an exception before commit() the destructor removes the staging directory, so an error
// leaves no partial result (an earlier result in the output directory is untouched).  Each file
// should itself be written with write_file_atomic / write_csv (durable on its own).
#include <filesystem>
#include <string>
#include <vector>

namespace errsep::io {

class StagedDirectory {
 public:
  /// Creates an empty staging directory "<parent>/.<name>.<tag>-partial-<pid>" for output
  /// directory `out` (its parent is created if needed).  Throws std::filesystem::filesystem_error.
  explicit StagedDirectory(const std::filesystem::path& out, const std::string& tag = "result");
  StagedDirectory(const StagedDirectory&) = delete;
  StagedDirectory& operator=(const StagedDirectory&) = delete;
  ~StagedDirectory();

  /// Where to write the files.
  const std::filesystem::path& dir() const { return dir_; }
  /// Moves the staged files into the output directory (renamed whole when it does not exist yet,
  /// else file by file, replacing files of the same name) and returns their final paths.
  std::vector<std::filesystem::path> commit();

 private:
  std::filesystem::path out_, dir_;
};

}  // namespace errsep::io

#pragma once
// Shared helpers for the Catch2 tests: paths of the source, build and ../shared trees, and a
// scratch directory that removes itself.
#include <filesystem>
#include <string>

namespace errsep::test {

inline std::filesystem::path source_dir() {
  return ERRSEP_SOURCE_DIR;
}
inline std::filesystem::path binary_dir() {
  return ERRSEP_BINARY_DIR;
}
inline std::filesystem::path shared_dir() {
  return ERRSEP_SHARED_DIR;
}
/// Path of an errsep app in the build tree, e.g. app_path("separate").
inline std::filesystem::path app_path(const std::string& name) {
  return binary_dir() / "apps" / ("errsep-" + name);
}

/// A fresh directory under the system temp dir, removed (recursively) on destruction.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

/// The 1-based line of data row `row` (0-based) of a CSV file written by errsep (metadata lines,
/// then the header, then the rows), for "file:line" expectations; 0 when it has no header.
std::size_t data_line(const std::filesystem::path& csv, std::size_t row);

/// Runs a shell command, returns its exit status (-1 if it did not exit normally) and its
/// combined stdout+stderr in `output`.
int run_command(const std::string& cmd, std::string* output = nullptr);

/// The whole content of a file ("" when it cannot be read).
std::string read_file(const std::filesystem::path& p);
/// Replaces the first `from` in `s` by `to`; throws std::runtime_error when there is none (a
/// test that edits a shipped config must notice when the config changes).
void replace_once(std::string& s, const std::string& from, const std::string& to);

}  // namespace errsep::test

#include "errsep/io/staged_directory.hpp"

#include <unistd.h>

namespace errsep::io {

namespace fs = std::filesystem;

StagedDirectory::StagedDirectory(const fs::path& out, const std::string& tag)
    : out_(out.lexically_normal()) {
  if (!out_.has_filename()) out_ = out_.parent_path();
  fs::path parent = out_.parent_path();
  if (parent.empty()) parent = ".";
  fs::create_directories(parent);
  dir_ = parent /
         ("." + out_.filename().string() + "." + tag + "-partial-" + std::to_string(::getpid()));
  fs::remove_all(dir_);
  fs::create_directory(dir_);
}

StagedDirectory::~StagedDirectory() {
  std::error_code ec;
  fs::remove_all(dir_, ec);  // after commit() it is gone already; on an error nothing stays
}

std::vector<fs::path> StagedDirectory::commit() {
  std::vector<fs::path> names;
  for (const auto& e : fs::directory_iterator(dir_))
    names.push_back(e.path().filename());
  if (!fs::exists(out_)) {
    fs::rename(dir_, out_);
  } else {
    for (const auto& n : names)
      fs::rename(dir_ / n, out_ / n);
    fs::remove(dir_);
  }
  std::vector<fs::path> files;
  for (const auto& n : names)
    files.push_back(out_ / n);
  return files;
}

}  // namespace errsep::io

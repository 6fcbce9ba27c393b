#include "errsep/io/default_config.hpp"

#include <stdexcept>
#include <system_error>
#include <vector>

#include "errsep/install_paths.hpp"

namespace errsep::io {

namespace fs = std::filesystem;

std::filesystem::path default_config_file(const std::string& name) {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  std::vector<fs::path> candidates;
  if (!ec) {
    const fs::path build = fs::weakly_canonical(kBinaryDir, ec);
    const fs::path exe_dir = self.parent_path();
    const auto rel = exe_dir.lexically_relative(build);
    if (!ec && !rel.empty() && *rel.begin() != "..")
      candidates.push_back(fs::path(kSourceDir) / "config" / name);
    candidates.push_back(
        (exe_dir / ".." / "share" / "errsep" / "config" / name).lexically_normal());
  }
  candidates.push_back(fs::path(kInstallDataDir) / "errsep" / "config" / name);
  std::string searched;
  for (const auto& c : candidates) {
    if (fs::is_regular_file(c, ec)) return c;
    searched += (searched.empty() ? "" : ", ") + c.string();
  }
  throw std::runtime_error("no --config given and the default " + name +
                           " is not where this errsep keeps it (searched " + searched +
                           "): give the machine config with --config FILE");
}

}  // namespace errsep::io

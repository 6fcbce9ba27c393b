#pragma once
// The machine config a command uses when it is given no --config: config/simulator.toml of this
// errsep, found from where the program is, not from the working directory (so that
// `errsep-scan` works from any directory, as the README's first job runs it).
#include <filesystem>
#include <string>

namespace errsep::io {

/// The config named `name` (e.g. "simulator.toml") of this errsep, looked for in order:
///  1. <source tree>/config/ when the running program lies in this build tree;
///  2. <program dir>/../share/errsep/config/ (an installed errsep, wherever it was installed);
///  3. <CMAKE_INSTALL_FULL_DATADIR>/errsep/config/.
/// Throws std::runtime_error listing the places searched when none holds it.
std::filesystem::path default_config_file(const std::string& name = "simulator.toml");

}  // namespace errsep::io

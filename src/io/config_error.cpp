#include "errsep/io/config_error.hpp"

namespace errsep::io {

ConfigError::ConfigError(const std::string& file, int line, const std::string& key,
                         const std::string& problem)
    : std::runtime_error(file + (line > 0 ? ":" + std::to_string(line) : std::string()) + ": " +
                         (key.empty() ? std::string() : key + ": ") + problem),
      key_(key),
      line_(line) {}

}  // namespace errsep::io

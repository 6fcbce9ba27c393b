#pragma once
// The one error of errsep's TOML configs (the machine config, the uncertainty-budget config):
// what() = "file:line: key: problem", the line 0 (left out) when unknown.
#include <stdexcept>
#include <string>

namespace errsep::io {

/// A problem in a config file.  what() = "file:line: key: problem".
class ConfigError : public std::runtime_error {
 public:
  ConfigError(const std::string& file, int line, const std::string& key,
              const std::string& problem);
  const std::string& key() const noexcept { return key_; }
  int line() const noexcept { return line_; }

 private:
  std::string key_;
  int line_;
};

}  // namespace errsep::io

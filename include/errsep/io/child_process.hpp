#pragma once
// Running a helper program (gnuplot for the figures, Chromium for the PDF) from the report code:
// one place that spawns, redirects, waits and times out.  Not real-time safe: it forks a process.
#include <filesystem>
#include <string>
#include <vector>

namespace errsep::io {

struct ChildRun {
  std::vector<std::string> argv;  ///< argv[0] is searched in PATH when it has no '/'
  std::filesystem::path cwd;      ///< working folder of the child; empty = this process's
  std::filesystem::path log;      ///< stdout and stderr go here; empty = /dev/null
  /// Killed (SIGKILL) after this long; 0 = wait for ever.
  double timeout_s = 0;
};

/// Runs the program to its end.  Returns its exit status, or -1 when it could not be started, was
/// killed by a signal or timed out; `why` then says which.
int run_child(const ChildRun& run, std::string* why);

}  // namespace errsep::io

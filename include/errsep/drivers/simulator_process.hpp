#pragma once
// Starts the device simulator (errsep-devsim) as a child process for the embedded default: no
// machine, the scan talks to a simulated one over real Modbus TCP on loopback.
//
// The child runs in its own process group, so a Ctrl-C in the terminal reaches the scan (which
// must still stop the simulated stages over Modbus) and not the simulator; the scan stops the
// simulator itself at the end (SIGTERM, then SIGKILL after a grace period).  However the program
// dies (SIGKILL, the OOM killer, a crash), the simulator dies with it: the child sets
// PR_SET_PDEATHSIG (SIGKILL) before exec, and exits at once when its parent died before that
// (parent pid changed).  The kernel sends the signal when the *thread* that started the child
// ends: construct a SimulatorProcess on a thread that lives as long as the program needs it (the
// main thread).  Each program starts its own simulator on an ephemeral port that it reads from the
// child's own stdout: it never talks to another program's simulator.
#include <sys/types.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

namespace errsep::drivers {

class SimulatorProcess {
 public:
  /// Runs `exe --config <config> --port 0 <extra_args...>` and waits up to `timeout` for its
  /// "listening <host>:<port>" line.  Throws std::runtime_error naming the executable when it
  /// cannot be started, exits early, or does not report a port in time.  Not real-time safe.
  SimulatorProcess(const std::filesystem::path& exe, const std::filesystem::path& config,
                   const std::vector<std::string>& extra_args = {},
                   std::chrono::milliseconds timeout = std::chrono::milliseconds(10000));
  ~SimulatorProcess();  ///< stop()
  SimulatorProcess(const SimulatorProcess&) = delete;
  SimulatorProcess& operator=(const SimulatorProcess&) = delete;

  int port() const noexcept { return port_; }
  pid_t pid() const noexcept { return pid_; }
  const std::string& host() const noexcept { return host_; }
  /// SIGTERM, wait up to 3 s, then SIGKILL; reaps the child.  Idempotent, never throws.
  /// Returns the child's exit status (or 128 + signal), -1 if it was already stopped.
  int stop() noexcept;

 private:
  pid_t pid_ = -1;
  int out_fd_ = -1;
  int port_ = 0;
  std::string host_;
  std::thread drain_;  // reads the child's stdout after the port line, so it never blocks
};

/// errsep-devsim next to the running executable (build/apps/), or "" when there is none.
std::filesystem::path default_devsim_path();

}  // namespace errsep::drivers

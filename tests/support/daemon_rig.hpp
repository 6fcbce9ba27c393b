#pragma once
// Test rig of the daemon tests: child processes that are always cleaned up (SIGKILL + waitpid in
// the destructor), a notify socket standing in for systemd, the Modbus client mbpoll (not written
// here) on the daemon's register map, and a rig that starts errsep-devsim + errsep-daemon on
// ephemeral loopback ports.
#include <sys/types.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "errsep/io/raw_scan_csv.hpp"
#include "support/support.hpp"

namespace errsep::test {

/// A child process with its stdout on a pipe and its stderr in a file.
class Child {
 public:
  /// Starts argv[0] (a path) with the current environment plus `env` ("KEY=value").  Throws
  /// std::runtime_error when it cannot be started.
  Child(const std::vector<std::string>& argv, const std::vector<std::string>& env,
        const std::filesystem::path& stderr_file);
  ~Child();  ///< SIGKILL and reap if still running
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;

  pid_t pid() const { return pid_; }
  bool running();
  void signal(int sig);
  /// Waits for the exit; returns the wait status, or nullopt at the timeout.
  std::optional<int> wait(std::chrono::milliseconds timeout);
  /// Reads stdout until a line starts with `prefix`; returns the rest of that line.
  std::optional<std::string> read_line(const std::string& prefix,
                                       std::chrono::milliseconds timeout);
  /// CPU time (user + system) used so far, seconds (from /proc/<pid>/stat).
  double cpu_seconds() const;

 private:
  pid_t pid_ = -1;
  int out_fd_ = -1;
  std::string buf_;
  std::optional<int> status_;
};

/// An AF_UNIX datagram socket bound to a path: what $NOTIFY_SOCKET names under systemd.  A thread
/// receives continuously (as systemd does), so the sender never meets a full queue.
class NotifyListener {
 public:
  explicit NotifyListener(std::filesystem::path path);
  ~NotifyListener();
  const std::filesystem::path& path() const { return path_; }
  /// Waits until a message received so far contains `needle`, or the timeout passes.
  bool wait_for(const std::string& needle, std::chrono::milliseconds timeout);
  std::vector<std::string> messages() const;
  bool seen(const std::string& needle) const;

 private:
  std::filesystem::path path_;
  int fd_ = -1;
  mutable std::mutex mu_;
  std::vector<std::string> messages_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

/// mbpoll -t 0: writes coil `coil` (0-based) = value.  Returns mbpoll's exit status; its output
/// in `out`.
int mbpoll_write_coil(int port, int coil, int value, std::string* out = nullptr);
/// mbpoll -t 3: reads `count` input registers from 0-based `start`; empty on failure.
std::vector<long> mbpoll_read_inputs(int port, int start, int count, std::string* out = nullptr);

/// errsep-devsim on an ephemeral (or given) loopback port.
struct Devsim {
  std::unique_ptr<Child> proc;
  int port = 0;
  /// Starts it and reads its "listening 127.0.0.1:<port>" line.
  void start(const std::filesystem::path& config, const std::filesystem::path& log, int port = 0);
  void kill();
};

/// The daemon under test: devsim + daemon + notify socket in a temp dir.
struct DaemonRig {
  TempDir tmp;
  std::filesystem::path config;
  std::filesystem::path results;
  Devsim devsim;
  std::unique_ptr<NotifyListener> notify;
  std::unique_ptr<Child> daemon;
  int modbus_port = 0;
  std::vector<std::string> env;  ///< extra environment of the daemon ("KEY=value")
  /// Command the daemon is started through (argv[0] a path, e.g. unshare ... sh -c '... exec
  /// "$@"' sh); it must exec the daemon in the same process.  Empty: the daemon itself.
  std::vector<std::string> prefix;

  DaemonRig();
  /// Starts the daemon (devsim must run, or `device_port` be given); reads its register-map
  /// port.  Does not wait for READY=1.
  void start_daemon(const std::vector<std::string>& extra_args = {});
  /// Input registers 0..kRegisterCount-1, or empty if the daemon does not answer.
  std::vector<long> registers();
  /// Polls the register map until pred(registers) or the timeout; returns the last registers.
  template <class Pred>
  std::vector<long> wait_regs(Pred pred, std::chrono::milliseconds timeout);
  /// Every store file of scan `id` ("<stem>.<kind>.csv"), by kind.
  std::optional<std::filesystem::path> find_file(std::uint64_t id, const std::string& kind) const;
  /// The result folder of scan `id` (results/<stem>/ beside its complete raw file), if there.
  std::optional<std::filesystem::path> result_folder(std::uint64_t id) const;
  /// Starts scan `id` as a PLC would (the start coil, through mbpoll) and waits until the map
  /// shows it ended and the daemon idle; returns the registers then (checked to be whole).
  std::vector<long> trigger_and_wait(std::uint64_t id, std::chrono::milliseconds timeout);
  /// Contents of the daemon's and devsim's stderr logs, for failure messages.
  std::string logs() const;
  /// Prints logs() to stderr when a REQUIRE failed (an exception leaves the test).
  ~DaemonRig();
};

template <class Pred>
std::vector<long> DaemonRig::wait_regs(Pred pred, std::chrono::milliseconds timeout) {
  const auto until = std::chrono::steady_clock::now() + timeout;
  std::vector<long> r;
  while (std::chrono::steady_clock::now() < until) {
    r = registers();
    if (r.size() >= 18 && pred(r)) return r;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return r;
}

/// Input registers of the daemon's map, version 2 (drivers/daemon_register_server.hpp).
inline constexpr std::size_t kRegisterCount = 18;

/// Register indices of the daemon's map (drivers/daemon_register_server.hpp).
enum Reg : int {
  reg_state = 0,
  reg_trigger = 1,
  reg_scan_id = 2,
  reg_points_done = 3,
  reg_points_total = 4,
  reg_scans_completed = 5,
  reg_last_scan_id = 6,
  reg_last_outcome = 7,
  reg_straightness_hi = 8,
  reg_straightness_lo = 9,
  reg_faults = 10,
  reg_version = 12,
  reg_trigger_source = 13,
  reg_straightness_lsq_hi = 14,
  reg_straightness_U_hi = 16,
};

/// An int32 nm pair of registers (high word first) in um; NaN for INT32_MIN (no value).
double nm_registers_um(const std::vector<long>& r, int hi);

/// Reads a store file as a consumer would and says what is wrong with it ("" = whole).  Each
/// check can fail on a truncated or half-written file: the file must end with a newline (a cut
/// inside a line loses it) and have exactly one row per slide position of the scan geometry (a
/// cut at a line boundary loses rows).
///  raw:            "# complete: true", every cell a finite number, positions = geometry,
///                  points_measured = 4P/4P;
///  raw-incomplete: "# complete: false", positions = geometry, as many finite readings as its
///                  points_measured says (at least one), NaN elsewhere;
///  result:         x_mm,S_um,gamma_urad,u_S_um, every cell a finite number, one row per
///                  position of `raw` (its raw file) at the same x, outcome complete.
/// `out`, when given, receives the parsed raw scan.
std::string check_raw_file(const std::filesystem::path& p, io::RawFourSensorScan* out = nullptr);
std::string check_checkpoint_file(const std::filesystem::path& p,
                                  io::RawFourSensorScan* out = nullptr);
std::string check_result_file(const std::filesystem::path& p, const io::RawFourSensorScan& raw);

/// Input registers of errsep-devsim (the simulated machine), e.g. a stage's status word.
std::vector<long> devsim_inputs(int port, int start, int count);

}  // namespace errsep::test

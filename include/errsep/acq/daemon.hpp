#pragma once
// The scan daemon: the state machine and main loop of errsep running as a service.
//
//   starting ──devices answer──▶ idle ──trigger──▶ scanning ──scan ends──▶ idle
//      │  ▲                       │  ▲                │
//      ▼  │ open fails / retry    ▼  │ check ok       ▼ device stops answering
//     fault ◀────────────────── check fails        fault (raw data kept, marked incomplete)
//   READY=1 after the first open attempt, into idle or fault alike (see "Readiness" below).
//   SIGTERM in any state ─▶ stopping: abort the scan, stop the stages, write what was measured,
//   exit within DaemonOptions::stop_timeout (plus the writing of the files; devices that do not
//   answer in time are left behind, the process exits regardless).
//
// One scan at a time: a trigger (Modbus coil, GPIO edge, schedule) while a scan runs, while in
// fault or while stopping is refused with a reason (TriggerReply + text) that the register map
// exposes to the cell controller, together with the source of that trigger.  GPIO: the backend's
// StartInput (a DigitalIo line) is watched by a thread of the daemon, a debounced rising edge is
// a trigger like the start coil.  Schedule: every tick is a trigger too, so a tick during a scan
// is refused and skipped, never queued into a second scan right after the first.  Each file
// records its trigger source (metadata "trigger").  SIGHUP reloads the machine config between
// scans: during a scan the reload waits for the scan to end, so no scan is dropped; a config with
// errors is reported and the old one kept.
//
// Readiness (sd_notify READY=1) means "the service is up and reports": it is sent once the
// config is loaded, the results directory is usable, the register map listens (it is started
// before run()) and the first attempt to open the devices has ended -- whatever its outcome.  A
// machine that is powered off at boot thus gives a started service in the fault state (STATUS=,
// register map, journal) that leaves the fault when the devices answer, instead of a start
// timeout and a restart loop.  Errors that no waiting can cure (a config with errors, an unusable
// results directory, a register map that cannot bind) end the process before READY=1.
//
// Checkpoints: while a scan runs, the main loop writes the raw data measured so far as the scan's
// raw-incomplete file (complete: false, outcome: in_progress) every checkpoint_interval (and
// never more often than ten times its own write time, so that long scans do not spend the main
// loop on it), atomically like every other file.  The final file replaces it (raw-incomplete) or
// makes it superfluous (raw: the checkpoint is then removed), so a SIGKILL or power cut mid-scan
// leaves the points measured up to the last checkpoint.  The sampling threads are not involved:
// the checkpoint is a copy of the ScanContext taken under its mutex by the main loop.  A scan
// whose complete raw file made it to disk but whose result did not (a stop between the two) gets
// its result at the next start, computed from the raw file (metadata result_recovered_utc).
//
// The main loop sleeps in poll() on a wake-up pipe (signals, triggers and the end of a scan write
// to it) with a timeout of at most the health-check / watchdog period: it never spins.  The scan
// itself runs on a worker thread through a ScanBackend (drivers/daemon_backend.hpp for real
// devices; tests may use their own), which records each measured point into the ScanContext, so
// the main thread can always write the raw data measured so far, even if the worker hangs.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <variant>
#include <vector>

#include "errsep/acq/digital_io.hpp"
#include "errsep/acq/sd_notify.hpp"
#include "errsep/core/displacement_joint.hpp"
#include "errsep/core/four_sensor.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "errsep/io/results_store.hpp"

namespace errsep::acq {

/// Values are part of the register map (status register 0): do not renumber.
enum class DaemonState : std::uint8_t {
  starting = 0,
  idle = 1,
  scanning = 2,
  fault = 3,
  stopping = 4
};
/// Values are part of the register map (status register 13): append only.
enum class TriggerSource : std::uint8_t { modbus, gpio, schedule, command, mqtt };
/// Reply to a trigger (status register 1): accepted or why not.
enum class TriggerReply : std::uint8_t {
  none = 0,
  accepted = 1,
  refused_scanning = 2,  ///< a scan is running
  refused_fault = 3,     ///< devices do not answer (fault state)
  refused_stopping = 4,  ///< the daemon is shutting down
  refused_starting = 5,  ///< devices not opened yet
  refused_pending = 6,   ///< a trigger was accepted and the scan is about to start
};
/// How a scan ended (status register 7).
enum class ScanOutcome : std::uint8_t {
  none = 0,
  complete = 1,
  aborted = 2,       ///< abort coil / abort request
  device_fault = 3,  ///< a device stopped answering or faulted
  stopped = 4,       ///< SIGTERM during the scan
  write_failed = 5,  ///< measured, but the results could not be written (disk full, ...)
};

const char* to_string(DaemonState s) noexcept;
const char* to_string(TriggerSource s) noexcept;
const char* to_string(TriggerReply r) noexcept;
const char* to_string(ScanOutcome o) noexcept;

/// A scan's raw record: the four-sensor method's or the displacement method's, as the scan's
/// begin() chose; the daemon writes either through the same overloads (std::visit).
using RawScan = std::variant<io::RawFourSensorScan, io::RawDisplacementScan>;

/// What a scan worker and the main loop share.  Thread-safe.
class ScanContext {
 public:
  ScanContext(std::uint64_t scan_id, const std::atomic<bool>& abort);
  std::uint64_t scan_id() const noexcept { return id_; }
  /// True once the scan is to stop (abort coil, SIGTERM).  Backends check it between steps.
  bool abort_requested() const noexcept { return abort_.load(std::memory_order_acquire); }
  const std::atomic<bool>& abort_flag() const noexcept { return abort_; }

  /// Backend: the layout of the scan (x_mm, geometry, metadata; m_um all NaN) before measuring.
  void begin(io::RawFourSensorScan layout);
  /// Backend: the layout of a displacement scan (x_mm, d_mm, metadata; readings NaN).
  void begin(io::RawDisplacementScan layout);
  /// Backend: one measured point of configuration `config` (0..3) at position index `n`; for a
  /// displacement scan `config` is acq::ScanHooks::cell's column (0 s1 scan 1, 1 s2 scan 1,
  /// 2 s1 scan 2, 3 s2 scan 2).
  void record(int config, std::size_t n, double m_um, double t_s);
  /// Backend: proof of life while waiting (a move, a settle time).
  void heartbeat() noexcept;
  /// Backend: the scan's own record once it has ended (acq::run_scan's raw scan, with the
  /// sampler's counters in its metadata), replacing the points recorded one by one.  Ignored when
  /// it is of the other method or its positions differ from begin()'s layout.
  void finish(io::RawFourSensorScan raw);
  void finish(io::RawDisplacementScan raw);

  /// The raw data measured so far (complete = false), of the method begin() chose (an empty
  /// four-sensor record before begin()).
  RawScan snapshot() const;
  std::uint32_t points_done() const noexcept { return done_.load(); }
  std::uint32_t points_total() const noexcept { return total_.load(); }
  /// CLOCK_MONOTONIC ns of the last record() or heartbeat().
  std::int64_t last_progress_ns() const noexcept { return progress_ns_.load(); }

 private:
  std::uint64_t id_;
  const std::atomic<bool>& abort_;
  mutable std::mutex mu_;
  RawScan raw_;
  std::atomic<std::uint32_t> done_{0}, total_{0};
  std::atomic<std::int64_t> progress_ns_{0};
};

/// How a backend's scan ended: complete, or why not.
struct ScanEnd {
  ScanOutcome outcome = ScanOutcome::complete;
  std::string message;  ///< empty when complete
};

/// The start input of a backend: a rising edge on `line` of `io` asks for a scan (a start button
/// or a PLC output), like the start coil.  `lamp_line` >= 0: an output set while a scan runs.
struct StartInput {
  DigitalIo* io = nullptr;  ///< null: no GPIO start input; owned by the backend, configured
  unsigned line = 0;
  int lamp_line = -1;
  std::string name;  ///< for the journal, e.g. "gpiochip0 line 17"
};

/// The devices side of the daemon.  Not thread-safe except where stated: the main loop calls
/// open()/check() only while no scan runs; run_scan() runs on the worker thread.
class ScanBackend {
 public:
  ScanBackend() = default;
  ScanBackend(const ScanBackend&) = delete;
  ScanBackend& operator=(const ScanBackend&) = delete;
  virtual ~ScanBackend() = default;
  /// Opens the devices; throws std::runtime_error naming the device that does not answer.
  virtual void open() = 0;
  /// One cheap request to every device kind: true when they answer, else `why`.
  virtual bool check(std::string* why) = 0;
  /// Runs one scan, recording into `ctx`, until complete, aborted or failed.  Must return soon
  /// after ctx.abort_requested() becomes true (it stops the stages itself).
  virtual ScanEnd run_scan(ScanContext& ctx) = 0;
  /// Stops every stage now.  Called by the main loop only while no scan runs (a running scan
  /// stops the stages itself on abort: a device connection serves one thread).
  virtual void stop_motion() noexcept = 0;
  /// One line for the journal ("machine config X: 5 sensors, 3 stages on 2 buses").
  virtual std::string describe() const = 0;
  /// The GPIO start input, valid from a successful open() until the backend is destroyed.  The
  /// daemon waits for edges on it from its own thread (wait_edge() only; set_output() from the
  /// main loop).  Default: none.
  virtual StartInput start_input() { return {}; }
};

/// Builds a backend from the current config (called at start and on SIGHUP).  Throws on config
/// errors (message "file:line: key: problem").
using BackendFactory = std::function<std::unique_ptr<ScanBackend>()>;

struct DaemonOptions {
  io::ResultsStoreOptions results;
  std::chrono::milliseconds check_interval{500};  ///< device check while idle / in fault
  /// SIGTERM → exit bound: the scan stops, the stages get their stop command and the devices
  /// are closed within it (a device that does not answer in time is left behind); only the
  /// writing of the scan's files comes on top.
  std::chrono::milliseconds stop_timeout{5000};
  /// Longest a scan may go without progress before the watchdog is no longer pinged (systemd
  /// then restarts a hung daemon).
  std::chrono::milliseconds scan_stall_limit{60000};
  /// Start a scan this often; 0 = no schedule.  A tick while a scan runs (or in fault) is
  /// refused and skipped, not queued: the schedule never produces two scans back to back.
  double schedule_interval_s = 0.0;
  /// GPIO start input: rising edges closer than this (kernel timestamps) to the previous one are
  /// contact bounce and ignored.
  std::chrono::milliseconds gpio_debounce{20};
  /// A running scan's raw data is written as a checkpoint (raw-incomplete) this often (and no
  /// more often than 10 times the last checkpoint's write time).
  std::chrono::milliseconds checkpoint_interval{1000};
  bool separate = true;  ///< compute and write the four-sensor result after a scan
  /// Writes a complete scan's result set into `dir` (results/<stem>/, the folder errsep-scan
  /// writes: raw.csv, motion.csv, reference.csv, lcurve.csv, residuals.csv, summary.txt,
  /// refine/) whole or not at all, and returns its separation, from which the daemon's result
  /// file (the store's index of the scan) is made.  errsep-daemon sets it to
  /// service::FourSensorPipeline (acq does not know the service layer).  Throws when the
  /// separation fails (the raw file is kept).  Empty: the daemon separates with core's default
  /// options and writes its result file alone (tests of the state machine).
  std::function<core::FourSensorResult(const io::RawFourSensorScan& raw,
                                       const std::filesystem::path& dir)>
      write_result_set;
  /// The same for a displacement scan (machine config [scan] method = "displacement"):
  /// errsep-daemon sets it to service::DisplacementPipeline.  Empty: the joint estimate with
  /// core's default options, the result file alone.
  std::function<core::OneAxisJointResult(const io::RawDisplacementScan& raw,
                                         const std::filesystem::path& dir)>
      write_displacement_result_set;
  /// Called on the main loop once a scan's files are on disk (each finished scan, and each
  /// result recovered at start), with its scan id and store stem: e.g. queue it for the plant's
  /// broker (service/plant_publisher.hpp).  Exceptions are logged, never stop the daemon.
  std::function<void(std::uint64_t scan_id, const std::string& stem)> on_scan_committed;

  bool is_valid(std::string* why = nullptr) const;
};

/// Everything the register map and the journal show.  A snapshot (copy).
struct DaemonStatus {
  DaemonState state = DaemonState::starting;
  std::string message;            ///< what the daemon is doing / why it is in fault
  std::uint64_t scan_id = 0;      ///< scan running now (0 = none)
  std::uint32_t points_done = 0;  ///< of the running scan
  std::uint32_t points_total = 0;
  std::uint64_t scans_completed = 0;  ///< since start
  std::uint64_t last_scan_id = 0;
  ScanOutcome last_outcome = ScanOutcome::none;
  /// Straightness of S(x) of the last result (ISO 230-1 straightness deviation, NaN: none):
  /// minimum-zone reference line (two parallel lines of smallest separation enclosing S)...
  double last_straightness_um = 0.0;
  double last_straightness_U_um = 0.0;    ///< ...its expanded uncertainty (k = 2, bound model)
  double last_straightness_lsq_um = 0.0;  ///< about the least-squares reference line
  std::string last_file;                  ///< the last file written
  TriggerReply last_trigger = TriggerReply::none;
  TriggerSource last_trigger_source = TriggerSource::command;  ///< of last_trigger
  std::uint64_t gpio_edges = 0;  ///< rising edges seen on the GPIO start input (debounced)
  std::string last_refusal;      ///< reason of the last refused trigger
  std::uint32_t faults = 0;      ///< times the fault state was entered
};

class Daemon {
 public:
  /// `notifier` must outlive the daemon.  Throws std::invalid_argument for invalid options and
  /// std::runtime_error when the results directory is unusable.
  Daemon(DaemonOptions opts, BackendFactory factory, const SdNotifier& notifier);
  ~Daemon();
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  /// The main loop; returns the process exit code once stopped (0 = clean stop).
  int run();

  /// Async-signal-safe (atomic store + write to a pipe): SIGTERM/SIGINT and SIGHUP handlers.
  void request_stop() noexcept;
  void request_reload() noexcept;

  /// Asks for a scan.  Thread-safe.  Refused (with `reason`) unless idle with no scan pending.
  TriggerReply trigger(TriggerSource source, std::string* reason = nullptr);
  /// Aborts the running scan (raw data kept, marked incomplete).  False when none runs.
  bool abort_scan();
  DaemonStatus status() const;

 private:
  void wake() noexcept;
  void set_state(DaemonState s, const std::string& message);
  void log(int priority, const std::string& msg) const;
  bool try_open();
  void start_scan(TriggerSource src);
  void finish_scan(bool stopping);
  /// The raw file (raw, or raw-incomplete), then the result of a complete scan.
  template <class Raw>
  void write_scan_files(const Raw& raw, const ScanEnd& end);
  struct ResultFigures {
    std::string file;
    double minimum_zone_um = 0, minimum_zone_U_um = 0, least_squares_um = 0;
  };
  /// Separates a complete raw scan and writes its result file (scan metadata `meta`); throws
  /// io::DiskFullError or std::exception.
  ResultFigures write_result(const std::string& stem, const io::RawFourSensorScan& raw,
                             const std::vector<std::pair<std::string, std::string>>& meta,
                             const std::string& raw_file);
  /// A displacement scan's: the joint estimate; the figures are of the table motion error m(x).
  ResultFigures write_result(const std::string& stem, const io::RawDisplacementScan& raw,
                             const std::vector<std::pair<std::string, std::string>>& meta,
                             const std::string& raw_file);
  /// The result file's metadata both kinds share: the scan's, the raw file's size and CRC.
  void result_file_metadata(io::CsvTable& t, const std::string& stem,
                            const std::vector<std::pair<std::string, std::string>>& meta,
                            const std::string& raw_file, bool result_dir) const;
  /// At start: the result of every complete raw file that has none (a stop between the two).
  int recover_results();
  void scan_committed(std::uint64_t scan_id, const std::string& stem);
  /// Metadata of the scan's raw/result files (scan id, trigger, times, outcome, points).
  std::vector<std::pair<std::string, std::string>> scan_metadata(const std::string& outcome,
                                                                 const std::string& reason) const;
  /// Main loop, during a scan: the raw data measured so far as the raw-incomplete file.
  void write_checkpoint();
  void do_reload();
  void ping_watchdog(std::int64_t now_ns);
  /// GPIO start input of the open backend: a thread waiting for its edges.
  void start_gpio_watch();
  void stop_gpio_watch() noexcept;
  void set_lamp(bool on) noexcept;

  DaemonOptions opts_;
  BackendFactory factory_;
  const SdNotifier& notify_;
  io::ResultsStore store_;
  std::unique_ptr<ScanBackend> backend_;
  bool backend_open_ = false;
  bool ready_sent_ = false;

  int wake_pipe_[2] = {-1, -1};
  std::atomic<bool> stop_{false}, reload_{false}, abort_{false};
  std::atomic<bool> pending_{false};
  /// The backend could not be built from the config (it changed on disk after the start): the
  /// daemon stays in fault until SIGHUP instead of re-reading the file on every check.
  bool config_failed_ = false;
  TriggerSource pending_source_ = TriggerSource::command;

  // What the scan worker hands back.  Shared with the worker thread rather than a member, so a
  // worker left behind at SIGTERM (hung in a device call) never touches the Daemon after it is
  // gone; it then writes only this and the wake-up pipe, which is left open for it.
  struct WorkerShared {
    ScanEnd end;
    std::atomic<bool> done{false};
  };
  std::unique_ptr<ScanContext> ctx_;
  std::thread worker_;
  std::shared_ptr<WorkerShared> worker_state_;
  bool worker_left_behind_ = false;
  std::uint64_t next_scan_id_ = 1;
  std::chrono::system_clock::time_point scan_start_{};
  TriggerSource scan_source_ = TriggerSource::command;
  std::string scan_stem_;
  bool stop_during_scan_ = false;
  // Checkpoints of the running scan.
  std::chrono::steady_clock::time_point next_checkpoint_{};
  std::uint32_t checkpoint_points_ = 0;  ///< points in the last checkpoint written
  bool checkpoint_on_disk_ = false;
  bool checkpoint_error_logged_ = false;
  bool reload_deferred_logged_ = false;
  std::string last_write_error_;  ///< of the last scan's files ("" = written)

  StartInput gpio_;
  std::thread gpio_thread_;
  std::atomic<bool> gpio_stop_{false};

  mutable std::mutex mu_;  // guards status_ and pending_source_
  DaemonStatus status_;
  std::int64_t last_ping_ns_ = 0;
};

}  // namespace errsep::acq

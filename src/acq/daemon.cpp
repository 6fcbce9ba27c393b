#include "errsep/acq/daemon.hpp"

#include <fcntl.h>
#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <sstream>

#if defined(__SANITIZE_ADDRESS__)
#include <sanitizer/lsan_interface.h>
#endif

#include "errsep/acq/digital_trigger.hpp"
#include "errsep/acq/sampler.hpp"  // monotonic_ns
#include "errsep/core/four_sensor.hpp"
#include "errsep/core/four_sensor_evaluation.hpp"
#include "errsep/core/iso230.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/staged_directory.hpp"
#include "errsep/io/utc_time.hpp"

namespace errsep::acq {
namespace {

// sd-daemon(3) priority prefixes: the journal reads them from stderr lines.
constexpr int kErr = 3, kWarning = 4, kInfo = 6;

constexpr std::int64_t kMsNs = 1'000'000;

std::string fmt(double v, int prec = 4) {
  std::ostringstream os;
  os.precision(prec);
  os << v;
  return os.str();
}

/// The daemon's scan metadata in front of the scan's own (acq::run_scan's), which it overrides
/// key by key (outcome, started_utc): one line per key in the raw file.
void prepend_metadata(std::vector<std::pair<std::string, std::string>>& md,
                      const std::vector<std::pair<std::string, std::string>>& daemon_md) {
  std::erase_if(md, [&](const auto& kv) {
    return std::any_of(daemon_md.begin(), daemon_md.end(),
                       [&](const auto& d) { return d.first == kv.first; });
  });
  md.insert(md.begin(), daemon_md.begin(), daemon_md.end());
}

/// A complete raw record the daemon can separate: a four-sensor one needs its geometry.
bool separable(const io::RawFourSensorScan& raw) {
  return raw.geometry.has_value();
}
bool separable(const io::RawDisplacementScan&) {
  return true;
}

/// Readings measured so far (finite cells) of a raw record.
std::size_t measured_cells(const io::RawFourSensorScan& raw) {
  std::size_t n = 0;
  for (const auto& col : raw.m_um)
    for (double v : col)
      n += std::isfinite(v) ? 1 : 0;
  return n;
}
std::size_t measured_cells(const io::RawDisplacementScan& raw) {
  std::size_t n = 0;
  for (const auto* col : {&raw.s1_scan1_um, &raw.s2_scan1_um, &raw.s1_scan2_um, &raw.s2_scan2_um})
    for (double v : *col)
      n += std::isfinite(v) ? 1 : 0;
  return n;
}

}  // namespace

const char* to_string(DaemonState s) noexcept {
  switch (s) {
    case DaemonState::starting:
      return "starting";
    case DaemonState::idle:
      return "idle";
    case DaemonState::scanning:
      return "scanning";
    case DaemonState::fault:
      return "fault";
    case DaemonState::stopping:
      return "stopping";
  }
  return "unknown";
}
const char* to_string(TriggerSource s) noexcept {
  switch (s) {
    case TriggerSource::modbus:
      return "modbus";
    case TriggerSource::gpio:
      return "gpio";
    case TriggerSource::schedule:
      return "schedule";
    case TriggerSource::command:
      return "command";
    case TriggerSource::mqtt:
      return "mqtt";
  }
  return "unknown";
}
const char* to_string(TriggerReply r) noexcept {
  switch (r) {
    case TriggerReply::none:
      return "none";
    case TriggerReply::accepted:
      return "accepted";
    case TriggerReply::refused_scanning:
      return "refused: a scan is running";
    case TriggerReply::refused_fault:
      return "refused: devices in fault";
    case TriggerReply::refused_stopping:
      return "refused: shutting down";
    case TriggerReply::refused_starting:
      return "refused: devices not ready yet";
    case TriggerReply::refused_pending:
      return "refused: a scan is about to start";
  }
  return "unknown";
}
const char* to_string(ScanOutcome o) noexcept {
  switch (o) {
    case ScanOutcome::none:
      return "none";
    case ScanOutcome::complete:
      return "complete";
    case ScanOutcome::aborted:
      return "aborted";
    case ScanOutcome::device_fault:
      return "device_fault";
    case ScanOutcome::stopped:
      return "stopped";
    case ScanOutcome::write_failed:
      return "write_failed";
  }
  return "unknown";
}

// --- ScanContext -----------------------------------------------------------------------------

ScanContext::ScanContext(std::uint64_t scan_id, const std::atomic<bool>& abort)
    : id_(scan_id), abort_(abort) {
  progress_ns_.store(monotonic_ns());
}

void ScanContext::begin(io::RawFourSensorScan layout) {
  std::lock_guard<std::mutex> lock(mu_);
  const std::size_t p = layout.x_mm.size();
  for (auto& col : layout.m_um)
    col.assign(p, std::numeric_limits<double>::quiet_NaN());
  std::array<std::vector<double>, 4> t;
  for (auto& col : t)
    col.assign(p, std::numeric_limits<double>::quiet_NaN());
  layout.t_s = t;
  layout.complete = false;
  raw_ = std::move(layout);
  total_.store(static_cast<std::uint32_t>(4 * p));
  done_.store(0);
  heartbeat();
}

void ScanContext::begin(io::RawDisplacementScan layout) {
  std::lock_guard<std::mutex> lock(mu_);
  const std::size_t k = layout.x_mm.size();
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  for (auto* v :
       {&layout.s1_scan1_um, &layout.s2_scan1_um, &layout.s1_scan2_um, &layout.s2_scan2_um})
    v->assign(k, kNaN);
  layout.t_scan1_s.emplace(k, kNaN);
  layout.t_scan2_s.emplace(k, kNaN);
  layout.complete = false;
  raw_ = std::move(layout);
  total_.store(static_cast<std::uint32_t>(4 * k));
  done_.store(0);
  heartbeat();
}

void ScanContext::record(int config, std::size_t n, double m_um, double t_s) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (auto* disp = std::get_if<io::RawDisplacementScan>(&raw_)) {
      if (config < 0 || config > 3 || n >= disp->x_mm.size()) return;
      // acq::ScanHooks::cell's columns: s1 and s2 of scan 1, then of scan 2.
      std::vector<double>* cols[4] = {&disp->s1_scan1_um, &disp->s2_scan1_um, &disp->s1_scan2_um,
                                      &disp->s2_scan2_um};
      (*cols[config])[n] = m_um;
      (*(config < 2 ? disp->t_scan1_s : disp->t_scan2_s))[n] = t_s;
    } else {
      auto& raw = std::get<io::RawFourSensorScan>(raw_);
      if (config < 0 || config > 3 || n >= raw.x_mm.size() || !raw.t_s) return;
      raw.m_um[static_cast<std::size_t>(config)][n] = m_um;
      (*raw.t_s)[static_cast<std::size_t>(config)][n] = t_s;
    }
  }
  done_.fetch_add(1);
  heartbeat();
}

void ScanContext::heartbeat() noexcept {
  progress_ns_.store(monotonic_ns());
}

void ScanContext::finish(io::RawFourSensorScan raw) {
  std::lock_guard<std::mutex> lock(mu_);
  const auto* layout = std::get_if<io::RawFourSensorScan>(&raw_);
  if (!layout || raw.x_mm.size() != layout->x_mm.size()) return;
  raw_ = std::move(raw);
}

void ScanContext::finish(io::RawDisplacementScan raw) {
  std::lock_guard<std::mutex> lock(mu_);
  const auto* layout = std::get_if<io::RawDisplacementScan>(&raw_);
  if (!layout || raw.x_mm.size() != layout->x_mm.size()) return;
  raw_ = std::move(raw);
}

RawScan ScanContext::snapshot() const {
  std::lock_guard<std::mutex> lock(mu_);
  return raw_;
}

// --- options ---------------------------------------------------------------------------------

bool DaemonOptions::is_valid(std::string* why) const {
  auto bad = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!results.is_valid(why)) return false;
  if (check_interval.count() < 10 || check_interval.count() > 600000)
    return bad("check_interval = " + std::to_string(check_interval.count()) +
               " ms: must be in [10, 600000]");
  if (stop_timeout.count() < 100)
    return bad("stop_timeout = " + std::to_string(stop_timeout.count()) + " ms: must be >= 100");
  if (scan_stall_limit.count() < 1000)
    return bad("scan_stall_limit = " + std::to_string(scan_stall_limit.count()) +
               " ms: must be >= 1000");
  if (!(schedule_interval_s >= 0) || (schedule_interval_s > 0 && schedule_interval_s < 1))
    return bad("schedule_interval_s = " + fmt(schedule_interval_s) + ": must be 0 or >= 1");
  if (gpio_debounce.count() < 0 || gpio_debounce.count() > 10000)
    return bad("gpio_debounce = " + std::to_string(gpio_debounce.count()) +
               " ms: must be in [0, 10000]");
  if (checkpoint_interval.count() < 50 || checkpoint_interval.count() > 600000)
    return bad("checkpoint_interval = " + std::to_string(checkpoint_interval.count()) +
               " ms: must be in [50, 600000]");
  return true;
}

// --- Daemon ----------------------------------------------------------------------------------

Daemon::Daemon(DaemonOptions opts, BackendFactory factory, const SdNotifier& notifier)
    : opts_([&] {
        std::string why;
        if (!opts.is_valid(&why)) throw std::invalid_argument("daemon options: " + why);
        return std::move(opts);
      }()),
      factory_(std::move(factory)),
      notify_(notifier),
      store_(opts_.results) {
  if (::pipe2(wake_pipe_, O_CLOEXEC | O_NONBLOCK) != 0)
    throw std::runtime_error("daemon: cannot create the wake-up pipe");
  status_.last_straightness_um = std::numeric_limits<double>::quiet_NaN();
  status_.last_straightness_U_um = std::numeric_limits<double>::quiet_NaN();
  status_.last_straightness_lsq_um = std::numeric_limits<double>::quiet_NaN();
}

Daemon::~Daemon() {
  stop_gpio_watch();
  if (worker_.joinable()) {
    abort_.store(true);
    worker_.join();
  }
  // A worker left behind at SIGTERM may still write its wake-up byte: its pipe stays open (the
  // process exits next), so that byte can never land in a descriptor reused for something else.
  if (!worker_left_behind_)
    for (int fd : wake_pipe_)
      if (fd >= 0) ::close(fd);
}

void Daemon::wake() noexcept {
  const char c = 1;
  // Non-blocking: a full pipe already guarantees a wake-up.
  [[maybe_unused]] const ssize_t n = ::write(wake_pipe_[1], &c, 1);
}

void Daemon::request_stop() noexcept {
  stop_.store(true);
  wake();
}

void Daemon::request_reload() noexcept {
  reload_.store(true);
  wake();
}

void Daemon::log(int priority, const std::string& msg) const {
  // One write per line so lines of different threads do not interleave.
  const std::string line = "<" + std::to_string(priority) + ">" + msg + "\n";
  [[maybe_unused]] const ssize_t n = ::write(2, line.data(), line.size());
}

void Daemon::set_state(DaemonState s, const std::string& message) {
  DaemonState old;
  {
    std::lock_guard<std::mutex> lock(mu_);
    old = status_.state;
    status_.state = s;
    status_.message = message;
    if (s == DaemonState::fault && old != DaemonState::fault) ++status_.faults;
  }
  const int prio = s == DaemonState::fault ? kErr : kInfo;
  if (old != s)
    log(prio, std::string("state ") + to_string(old) + " -> " + to_string(s) + ": " + message);
  notify_.status(std::string(to_string(s)) + ": " + message);
}

TriggerReply Daemon::trigger(TriggerSource source, std::string* reason) {
  TriggerReply r;
  std::string why;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stop_.load()) {
      r = TriggerReply::refused_stopping;
    } else {
      switch (status_.state) {
        case DaemonState::idle:
          r = pending_.load() ? TriggerReply::refused_pending : TriggerReply::accepted;
          break;
        case DaemonState::scanning:
          r = TriggerReply::refused_scanning;
          break;
        case DaemonState::fault:
          r = TriggerReply::refused_fault;
          break;
        case DaemonState::stopping:
          r = TriggerReply::refused_stopping;
          break;
        case DaemonState::starting:
          r = TriggerReply::refused_starting;
          break;
        default:
          r = TriggerReply::refused_fault;
      }
    }
    status_.last_trigger = r;
    status_.last_trigger_source = source;
    if (r == TriggerReply::accepted) {
      pending_.store(true);
      pending_source_ = source;
    } else {
      why = std::string(to_string(r));
      if (status_.state == DaemonState::scanning)
        why += " (scan " + std::to_string(status_.scan_id) + ")";
      else if (status_.state == DaemonState::fault)
        why += " (" + status_.message + ")";
      status_.last_refusal = std::string(to_string(source)) + ": " + why;
    }
  }
  if (r == TriggerReply::accepted) {
    log(kInfo, std::string("trigger from ") + to_string(source) + ": accepted");
    wake();
  } else {
    log(kWarning, std::string("trigger from ") + to_string(source) + " " + why);
  }
  if (reason) *reason = why;
  return r;
}

bool Daemon::abort_scan() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (status_.state != DaemonState::scanning) return false;
  }
  abort_.store(true);
  log(kWarning, "abort requested");
  wake();
  return true;
}

DaemonStatus Daemon::status() const {
  std::lock_guard<std::mutex> lock(mu_);
  DaemonStatus s = status_;
  if (ctx_) {
    s.points_done = ctx_->points_done();
    s.points_total = ctx_->points_total();
  }
  return s;
}

bool Daemon::try_open() {
  // A config error stays an error until SIGHUP (the file is not re-read on every check); a
  // device that does not answer is retried with the config loaded.
  if (!backend_) {
    if (config_failed_) return false;
    try {
      backend_ = factory_();
      log(kInfo, backend_->describe());
    } catch (const std::exception& e) {
      config_failed_ = true;
      set_state(DaemonState::fault,
                std::string("configuration: ") + e.what() + " (fix it and send SIGHUP)");
      return false;
    }
  }
  try {
    backend_->open();  // opens every device from scratch
    backend_open_ = true;
    start_gpio_watch();
    return true;
  } catch (const std::exception& e) {
    stop_gpio_watch();
    backend_open_ = false;
    set_state(DaemonState::fault, std::string("cannot open devices: ") + e.what());
    return false;
  }
}

void Daemon::ping_watchdog(std::int64_t now_ns) {
  const auto wd = notify_.watchdog_interval();
  if (wd.count() <= 0) return;
  const std::int64_t half_ns = wd.count() * 1000 / 2;
  if (now_ns - last_ping_ns_ < half_ns) return;
  // Prove progress: during a scan, only while the scan worker shows signs of life.
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (ctx_ && now_ns - ctx_->last_progress_ns() > opts_.scan_stall_limit.count() * kMsNs) {
      return;
    }
  }
  notify_.watchdog();
  last_ping_ns_ = now_ns;
}

void Daemon::start_gpio_watch() {
  stop_gpio_watch();
  gpio_ = backend_ ? backend_->start_input() : StartInput{};
  if (!gpio_.io) return;
  log(kInfo, "GPIO start input " + gpio_.name + ": a rising edge starts a scan" +
                 (gpio_.lamp_line >= 0
                      ? "; line " + std::to_string(gpio_.lamp_line) + " is on while a scan runs"
                      : std::string()));
  gpio_stop_.store(false);
  gpio_thread_ = std::thread([this, in = gpio_] {
    const std::int64_t debounce_ns = opts_.gpio_debounce.count() * kMsNs;
    bool have_last = false, reported = false;
    std::int64_t last_ns = 0;
    while (!gpio_stop_.load()) {
      EdgeEvent ev;
      const IoStatus st =
          wait_for_rising_edge(*in.io, in.line, std::chrono::seconds(1), ev, &gpio_stop_);
      if (st == IoStatus::timeout) continue;
      if (st != IoStatus::ok) {
        // A failing chip must not make this thread spin: report once, retry every 200 ms.
        if (!reported)
          log(kWarning, "GPIO start input " + in.name + ": " + to_string(st) + " (retrying)");
        reported = true;
        for (int i = 0; i < 10 && !gpio_stop_.load(); ++i)
          std::this_thread::sleep_for(std::chrono::milliseconds(20));
        continue;
      }
      if (reported) log(kInfo, "GPIO start input " + in.name + ": answers again");
      reported = false;
      // Contact bounce: edges within the debounce time of the last accepted one are the same
      // press.  Kernel timestamps, so a late wake-up of this thread does not matter.
      if (have_last && ev.t_ns - last_ns < debounce_ns) continue;
      have_last = true;
      last_ns = ev.t_ns;
      {
        std::lock_guard<std::mutex> lock(mu_);
        ++status_.gpio_edges;
      }
      trigger(TriggerSource::gpio);  // refused with a reason while a scan runs, like the coil
    }
  });
}

void Daemon::stop_gpio_watch() noexcept {
  gpio_stop_.store(true);
  if (gpio_thread_.joinable()) gpio_thread_.join();
  gpio_ = {};
}

void Daemon::set_lamp(bool on) noexcept {
  if (gpio_.io && gpio_.lamp_line >= 0) {
    const IoStatus st = gpio_.io->set_output(static_cast<unsigned>(gpio_.lamp_line), on);
    if (st != IoStatus::ok)
      log(kWarning, "GPIO lamp line " + std::to_string(gpio_.lamp_line) + ": " + to_string(st));
  }
}

void Daemon::start_scan(TriggerSource src) {
  const std::uint64_t id = next_scan_id_++;
  scan_start_ = std::chrono::system_clock::now();
  scan_source_ = src;
  scan_stem_ = io::ResultsStore::stem(scan_start_, id);
  next_checkpoint_ = std::chrono::steady_clock::now() + opts_.checkpoint_interval;
  checkpoint_points_ = 0;
  checkpoint_on_disk_ = false;
  checkpoint_error_logged_ = false;
  abort_.store(false);
  {
    std::lock_guard<std::mutex> lock(mu_);
    ctx_ = std::make_unique<ScanContext>(id, abort_);
    status_.scan_id = id;
  }
  // The state says scanning before the pending request is cleared: a trigger in between sees
  // "a scan is about to start" or "a scan is running", never an idle daemon with nothing pending
  // (which it would accept, and a second scan would follow this one).
  set_state(DaemonState::scanning,
            "scan " + std::to_string(id) + " (" + to_string(src) + ") " + scan_stem_);
  pending_.store(false);
  set_lamp(true);
  ScanContext* ctx = ctx_.get();
  ScanBackend* be = backend_.get();
  auto shared = std::make_shared<WorkerShared>();
  worker_state_ = shared;
  const int wake_fd = wake_pipe_[1];
  worker_ = std::thread([shared, ctx, be, wake_fd] {
    ScanEnd end;
    try {
      end = be->run_scan(*ctx);
    } catch (const std::exception& e) {
      end = {ScanOutcome::device_fault, e.what()};
    }
    shared->end = std::move(end);
    shared->done.store(true);
    const char c = 1;
    [[maybe_unused]] const ssize_t n = ::write(wake_fd, &c, 1);
  });
}

std::vector<std::pair<std::string, std::string>> Daemon::scan_metadata(
    const std::string& outcome, const std::string& reason) const {
  std::vector<std::pair<std::string, std::string>> meta = {
      {"scan_id", std::to_string(ctx_->scan_id())},
      {"trigger", to_string(scan_source_)},
      {"started_utc", io::utc_iso(scan_start_)}};
  if (outcome == "in_progress")
    meta.emplace_back("checkpoint_utc", io::utc_iso(std::chrono::system_clock::now()));
  else
    meta.emplace_back("ended_utc", io::utc_iso(std::chrono::system_clock::now()));
  meta.emplace_back("outcome", outcome);
  if (!reason.empty()) meta.emplace_back("outcome_reason", reason);
  return meta;
}

void Daemon::write_checkpoint() {
  using clock = std::chrono::steady_clock;
  const auto t0 = clock::now();
  next_checkpoint_ = t0 + opts_.checkpoint_interval;
  // The copy is taken under the context's mutex, which the scan worker holds only to store one
  // point: the sampling threads never see it.
  // Either kind of raw record, as its own CSV table.
  const auto checkpoint_of = [this](auto raw, std::size_t* measured) {
    *measured = measured_cells(raw);
    if (raw.x_mm.empty() || *measured == 0 || *measured == checkpoint_points_)
      return std::optional<io::CsvTable>();
    raw.complete = false;
    auto meta = scan_metadata("in_progress",
                              "checkpoint of a running scan: if this file is still here and "
                              "named raw-incomplete, the daemon stopped before the scan ended");
    meta.emplace_back("points_measured",
                      std::to_string(*measured) + "/" + std::to_string(ctx_->points_total()));
    prepend_metadata(raw.metadata, meta);
    return std::optional<io::CsvTable>(io::to_csv_table(raw));
  };
  std::size_t measured = 0;
  const auto table = std::visit([&](auto raw) { return checkpoint_of(std::move(raw), &measured); },
                                ctx_->snapshot());
  if (!table) return;
  try {
    store_.write(scan_stem_, "raw-incomplete", io::format_csv(*table, 12));
    checkpoint_points_ = static_cast<std::uint32_t>(measured);
    checkpoint_on_disk_ = true;
  } catch (const std::exception& e) {
    // Measuring goes on: the space may come back before the scan ends.  Reported once a scan.
    if (!checkpoint_error_logged_)
      log(kErr, "scan " + std::to_string(ctx_->scan_id()) +
                    ": checkpoint not written: " + e.what() + " (the scan goes on)");
    checkpoint_error_logged_ = true;
  }
  // Never spend more than ~10 % of the main loop on checkpoints (long scans, slow disks).
  const auto cost = clock::now() - t0;
  next_checkpoint_ = std::max(next_checkpoint_, clock::now() + 10 * cost);
}

Daemon::ResultFigures Daemon::write_result(
    const std::string& stem, const io::RawFourSensorScan& raw,
    const std::vector<std::pair<std::string, std::string>>& meta, const std::string& raw_file) {
  core::FourSensorResult r;
  const std::filesystem::path result_dir = store_.dir() / stem;
  if (opts_.write_result_set) {
    // The scan's result folder, as errsep-scan writes it, made visible whole before this file:
    // a stop between the two leaves no result file, so the next start makes both again.
    r = opts_.write_result_set(raw, result_dir);
  } else {
    Eigen::MatrixXd m(static_cast<Eigen::Index>(raw.positions()), 4);
    for (std::size_t i = 0; i < 4; ++i)
      for (std::size_t n = 0; n < raw.positions(); ++n)
        m(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(i)) = raw.m_um[i][n];
    r = core::separate_four_sensor(*raw.geometry, m, core::FourSensorOptions{});
  }
  io::CsvTable t;
  t.set_meta("format", "errsep four-sensor result");
  result_file_metadata(t, stem, meta, raw_file, static_cast<bool>(opts_.write_result_set));
  t.set_meta("solver", r.brief_report());
  t.set_meta("lambda", fmt(r.lambda, 6));
  t.set_meta("sigma_hat_um", fmt(r.sigma_um, 6));
  const auto n = static_cast<std::size_t>(r.x_mm.size());
  std::vector<double> x(n), s(n), g(n), us(n);
  for (std::size_t k = 0; k < n; ++k) {
    const auto e = static_cast<Eigen::Index>(k);
    x[k] = r.x_mm(e);
    s[k] = r.S_um(e);
    g[k] = r.gamma_rad(e) * 1e6;
    us[k] = r.u_S_um.size() == r.x_mm.size() ? r.u_S_um(e) : 0.0;
  }
  // ISO 230-1 straightness deviation: S(x) carries a line the separation cannot fix (and the
  // slide's alignment to the reference adds one), so the figure is taken about a reference line,
  // never as max - min of S.  Both references; the register map shows the minimum zone (the
  // smallest zone enclosing S, ISO 12780-1).  U from the separation's covariance, the noise's
  // bias of max - min removed (core/four_sensor_evaluation.hpp), as errsep-scan writes it.
  const core::StraightnessEstimate mz =
      core::four_sensor_straightness(r, core::ReferenceLine::minimum_zone);
  const core::StraightnessEstimate ls =
      core::four_sensor_straightness(r, core::ReferenceLine::least_squares);
  t.set_meta("straightness_minimum_zone_um", fmt(mz.straightness_um, 6));
  t.set_meta("straightness_minimum_zone_U_um", fmt(mz.expanded_um, 6));
  t.set_meta("straightness_minimum_zone_of_estimate_um", fmt(mz.zone.straightness_um, 6));
  t.set_meta("straightness_least_squares_um", fmt(ls.straightness_um, 6));
  t.set_meta("straightness_least_squares_U_um", fmt(ls.expanded_um, 6));
  t.set_meta("straightness_least_squares_of_estimate_um", fmt(ls.zone.straightness_um, 6));
  t.set_meta("straightness_U_note",
             "k = 2, from the separation's posterior covariance (core/four_sensor_evaluation.hpp)");
  if (!r.determination_note.empty()) t.set_meta("not_determined", r.determination_note);
  t.add_column("x_mm", x);
  t.add_column("S_um", s);
  t.add_column("gamma_urad", g);
  t.add_column("u_S_um", us);
  ResultFigures out;
  out.file = store_.write(stem, "result", io::format_csv(t, 10)).string();
  out.minimum_zone_um = mz.straightness_um;
  out.minimum_zone_U_um = mz.expanded_um;
  out.least_squares_um = ls.straightness_um;
  return out;
}

void Daemon::result_file_metadata(io::CsvTable& t, const std::string& stem,
                                  const std::vector<std::pair<std::string, std::string>>& meta,
                                  const std::string& raw_file, bool result_dir) const {
  if (result_dir) t.set_meta("result_dir", stem);
  for (const auto& [k, v] : meta)
    t.set_meta(k, v);
  t.set_meta("raw_file", std::filesystem::path(raw_file).filename().string());
  // The raw file this result is of, by content: the store's reader (recover_results) and any
  // consumer can tell a result from its raw file's run from one that is not.
  const auto [bytes, crc] = io::file_size_and_crc32(raw_file);
  char hex[16];
  std::snprintf(hex, sizeof hex, "%08x", crc);
  t.set_meta("raw_bytes", std::to_string(bytes));
  t.set_meta("raw_crc32", hex);
}

Daemon::ResultFigures Daemon::write_result(
    const std::string& stem, const io::RawDisplacementScan& raw,
    const std::vector<std::pair<std::string, std::string>>& meta, const std::string& raw_file) {
  core::OneAxisJointResult r;
  if (opts_.write_displacement_result_set) {
    // The scan's result folder, as errsep-scan writes it, whole before this file (as above).
    r = opts_.write_displacement_result_set(raw, store_.dir() / stem);
  } else {
    const auto vec = [](const std::vector<double>& v) {
      return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
    };
    core::DisplacementOptions o;
    o.sample_interval_mm = raw.x_mm.size() > 1 ? raw.x_mm[1] - raw.x_mm[0] : raw.d_mm;
    o.displacement_mm = raw.d_mm;
    r = core::separate_displacement_joint(vec(raw.s1_scan1_um), vec(raw.s2_scan1_um),
                                          vec(raw.s2_scan2_um), vec(raw.s1_scan2_um), o);
  }
  io::CsvTable t;
  t.set_meta("format", "errsep displacement result");
  result_file_metadata(t, stem, meta, raw_file,
                       static_cast<bool>(opts_.write_displacement_result_set));
  t.set_meta("solver", r.estimate.brief_report());
  t.set_meta("sigma_hat_um", fmt(r.sigma_um, 6));  // the key the scan summaries read
  t.set_meta("sigma_source", r.sigma_source);
  // ISO 230-1 straightness of the table motion error m(x) (Haramiishi 2024 Eq. 2), about both
  // reference lines; U (k = 2) from the joint estimate's u(m) when it has one, else none (NaN).
  const std::vector<double> x(raw.x_mm.begin(), raw.x_mm.end());
  const std::vector<double> m(r.estimate.m_um.data(),
                              r.estimate.m_um.data() + r.estimate.m_um.size());
  const std::vector<double> um(r.u_m_um.data(), r.u_m_um.data() + r.u_m_um.size());
  const auto mz = core::evaluate_straightness(x, m, um, core::ReferenceLine::minimum_zone);
  const auto ls = core::evaluate_straightness(x, m, um, core::ReferenceLine::least_squares);
  const double kNaN = std::numeric_limits<double>::quiet_NaN();
  const double mz_U = um.empty() ? kNaN : mz.uncertainty.expanded;
  t.set_meta("straightness_of", "m(x), the table motion error");
  t.set_meta("straightness_minimum_zone_um", fmt(mz.straightness_um, 6));
  t.set_meta("straightness_minimum_zone_U_um", fmt(mz_U, 6));
  t.set_meta("straightness_least_squares_um", fmt(ls.straightness_um, 6));
  t.set_meta("straightness_least_squares_U_um",
             fmt(um.empty() ? kNaN : ls.uncertainty.expanded, 6));
  t.add_column("x_mm", x);
  t.add_column("m_um", m);
  t.add_column("w_um", std::vector<double>(r.estimate.w_um.data(),
                                           r.estimate.w_um.data() + r.estimate.w_um.size()));
  if (!um.empty()) t.add_column("u_m_um", um);
  ResultFigures out;
  out.file = store_.write(stem, "result", io::format_csv(t, 10)).string();
  out.minimum_zone_um = mz.straightness_um;
  out.minimum_zone_U_um = mz_U;
  out.least_squares_um = ls.straightness_um;
  return out;
}

int Daemon::recover_results() {
  // A complete raw file is the scan: the result is computed from it alone.  The daemon stopped
  // (SIGKILL, power cut) between writing the one and the other; the result is made now, with
  // the raw file's scan metadata, so that no complete scan is left without its result.
  int made = 0;
  std::set<std::string> raw_stems, result_stems;
  for (const auto& f : store_.list()) {
    if (f.kind == "raw") raw_stems.insert(f.stem);
    if (f.kind == "result") result_stems.insert(f.stem);
  }
  for (const auto& stem : raw_stems) {
    const auto raw_path = store_.path(stem, "raw");
    if (result_stems.count(stem)) {
      // A result must be of its raw file (raw_bytes / raw_crc32, written since issue 21): one
      // that is not is made again, as if missing.  Older results without them are kept.
      try {
        const io::CsvTable res = io::read_csv(store_.path(stem, "result"));
        const auto want = res.meta("raw_crc32");
        char hex[16];
        std::snprintf(hex, sizeof hex, "%08x", io::file_size_and_crc32(raw_path).second);
        if (!want || *want == hex) continue;
        log(kWarning, "result of " + raw_path.filename().string() + " is of another raw file (" +
                          "raw_crc32 " + *want + ", the raw file's is " + hex +
                          "): made again from the raw file");
      } catch (const std::exception& e) {
        log(kWarning, "result of " + raw_path.filename().string() + " cannot be read (" + e.what() +
                          "): made again from the raw file");
      }
    }
    // Either kind of raw scan (its "# format:" line says which).
    const auto recover = [&](const auto& raw) {
      std::vector<std::pair<std::string, std::string>> meta;
      for (const char* key : {"scan_id", "trigger", "started_utc", "ended_utc", "outcome",
                              "outcome_reason", "points_measured"})
        if (const auto v = raw.meta(key)) meta.emplace_back(key, *v);
      meta.emplace_back("result_recovered_utc", io::utc_iso(std::chrono::system_clock::now()));
      const ResultFigures f = write_result(stem, raw, meta, raw_path.string());
      log(kWarning, "result of " + raw_path.filename().string() +
                        " was missing (the daemon stopped before writing it): computed "
                        "from the raw file, wrote " +
                        f.file);
      ++made;
      if (const auto id = raw.meta("scan_id")) scan_committed(std::stoull(*id), stem);
    };
    try {
      const io::CsvTable head = io::read_csv(raw_path, {.allow_non_finite = true, .min_rows = 0});
      if (head.meta("format").value_or("").find("displacement") != std::string::npos) {
        recover(io::read_raw_displacement_csv(raw_path));
      } else {
        const io::RawFourSensorScan raw = io::read_raw_four_sensor_csv(raw_path);
        if (!raw.geometry) throw std::runtime_error("no scan geometry in its metadata");
        recover(raw);
      }
    } catch (const std::exception& e) {
      log(kErr, "result of " + raw_path.filename().string() +
                    " is missing and could not be made: " + e.what());
    }
  }
  return made;
}

template <class Raw>
void Daemon::write_scan_files(const Raw& raw_in, const ScanEnd& end) {
  Raw raw = raw_in;
  raw.complete = end.outcome == ScanOutcome::complete;
  const std::uint64_t id = ctx_->scan_id();
  auto meta = scan_metadata(to_string(end.outcome), end.message);
  meta.emplace_back("points_measured", std::to_string(ctx_->points_done()) + "/" +
                                           std::to_string(ctx_->points_total()));
  prepend_metadata(raw.metadata, meta);
  last_write_error_.clear();

  ScanOutcome outcome = end.outcome;
  std::string last_file;
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  double straightness = kNaN, straightness_U = kNaN, straightness_lsq = kNaN;
  try {
    const std::string kind = raw.complete ? "raw" : "raw-incomplete";
    last_file = store_.write(scan_stem_, kind, io::format_csv(io::to_csv_table(raw), 12)).string();
    log(raw.complete ? kInfo : kWarning,
        "scan " + std::to_string(id) + " " + to_string(end.outcome) + ": wrote " + last_file);
    // The complete raw file supersedes the checkpoint (an incomplete one replaced it already).
    if (raw.complete && checkpoint_on_disk_) {
      try {
        store_.remove(scan_stem_, "raw-incomplete");
      } catch (const std::exception& e) {
        log(kWarning, "scan " + std::to_string(id) + ": " + e.what() +
                          " (removed at the next start: the raw file supersedes it)");
      }
    }
    checkpoint_on_disk_ = false;
    if (raw.complete && opts_.separate && separable(raw)) {
      try {
        const ResultFigures f = write_result(scan_stem_, raw, meta, last_file);
        last_file = f.file;
        straightness = f.minimum_zone_um;
        straightness_U = f.minimum_zone_U_um;
        straightness_lsq = f.least_squares_um;
        log(kInfo, "scan " + std::to_string(id) + ": straightness " + fmt(straightness) +
                       " um (minimum zone), " + fmt(straightness_lsq) +
                       " um (least squares); wrote " + last_file);
      } catch (const io::DiskFullError&) {
        throw;
      } catch (const std::exception& e) {
        log(kWarning,
            "scan " + std::to_string(id) + ": separation failed: " + e.what() + " (raw data kept)");
      }
    }
  } catch (const io::DiskFullError& e) {
    outcome = ScanOutcome::write_failed;
    last_write_error_ = "disk full";
    log(kErr, std::string("scan ") + std::to_string(id) +
                  ": disk full, results not written: " + e.what());
  } catch (const std::exception& e) {
    outcome = ScanOutcome::write_failed;
    last_write_error_ = e.what();
    log(kErr, std::string("scan ") + std::to_string(id) + ": results not written: " + e.what());
  }
  if (outcome == ScanOutcome::write_failed && checkpoint_on_disk_)
    log(kWarning, "scan " + std::to_string(id) + ": its last checkpoint (" +
                      std::to_string(checkpoint_points_) + " points) stays on disk as " +
                      store_.path(scan_stem_, "raw-incomplete").string());
  {
    std::lock_guard<std::mutex> lock(mu_);
    status_.last_scan_id = id;
    status_.last_outcome = outcome;
    status_.last_straightness_um = straightness;
    status_.last_straightness_U_um = straightness_U;
    status_.last_straightness_lsq_um = straightness_lsq;
    if (!last_file.empty()) status_.last_file = last_file;
    if (outcome == ScanOutcome::complete) ++status_.scans_completed;
  }
  // A scan whose files could not be written has nothing on disk to forward.
  if (outcome != ScanOutcome::write_failed) scan_committed(id, scan_stem_);
}

void Daemon::scan_committed(std::uint64_t scan_id, const std::string& stem) {
  if (!opts_.on_scan_committed) return;
  try {
    opts_.on_scan_committed(scan_id, stem);
  } catch (const std::exception& e) {
    log(kErr, "scan " + std::to_string(scan_id) + ": after writing: " + e.what());
  }
}

void Daemon::finish_scan(bool stopping) {
  worker_.join();
  set_lamp(false);
  ScanEnd end = worker_state_->end;
  worker_state_.reset();
  if (stopping && end.outcome == ScanOutcome::aborted) end.outcome = ScanOutcome::stopped;
  if (stopping && end.outcome == ScanOutcome::complete &&
      ctx_->points_done() < ctx_->points_total())
    end.outcome = ScanOutcome::stopped;
  std::visit([&](const auto& raw) { write_scan_files(raw, end); }, ctx_->snapshot());
  const std::uint64_t id = ctx_->scan_id();
  {
    std::lock_guard<std::mutex> lock(mu_);
    ctx_.reset();
    status_.scan_id = 0;
  }
  if (opts_.results.retention.enabled()) {
    const int n = store_.prune(std::chrono::system_clock::now());
    if (n > 0) log(kInfo, "retention: removed " + std::to_string(n) + " old result files");
  }
  if (stopping) return;
  const DaemonStatus st = status();
  if (end.outcome == ScanOutcome::device_fault)
    set_state(DaemonState::fault, "scan " + std::to_string(id) + ": " + end.message);
  else
    set_state(DaemonState::idle,
              "last scan " + std::to_string(id) + " " + to_string(st.last_outcome) +
                  (last_write_error_.empty() ? std::string() : " (" + last_write_error_ + ")") +
                  (std::isnan(st.last_straightness_um)
                       ? std::string()
                       : ", straightness " + fmt(st.last_straightness_um) + " um"));
}

void Daemon::do_reload() {
  reload_.store(false);
  notify_.reloading();
  log(kInfo, "SIGHUP: reloading the configuration");
  std::unique_ptr<ScanBackend> fresh;
  try {
    fresh = factory_();
  } catch (const std::exception& e) {
    log(kErr, std::string("reload failed, keeping the previous configuration: ") + e.what());
    notify_.ready();
    return;
  }
  log(kInfo, fresh->describe());
  stop_gpio_watch();
  backend_.reset();  // closes the old devices before the new ones open the same endpoints
  backend_ = std::move(fresh);
  backend_open_ = false;
  config_failed_ = false;
  try {
    backend_->open();
    backend_open_ = true;
    start_gpio_watch();
    set_state(DaemonState::idle, "configuration reloaded");
  } catch (const std::exception& e) {
    stop_gpio_watch();
    set_state(DaemonState::fault, std::string("cannot open devices: ") + e.what());
  }
  notify_.ready();
}

int Daemon::run() {
  const int stale = store_.clean_stale_temporaries();
  if (stale > 0)
    log(kWarning, "removed " + std::to_string(stale) +
                      " temporary files left by an interrupted write in " + store_.dir().string());
  const int superseded = store_.remove_superseded();
  if (superseded > 0)
    log(kWarning, "removed " + std::to_string(superseded) +
                      " checkpoints whose complete raw file was written before the daemon stopped");
  if (opts_.separate) recover_results();
  next_scan_id_ = store_.next_scan_id();
  log(kInfo, "results in " + store_.dir().string() + ", next scan id " +
                 std::to_string(next_scan_id_) +
                 (opts_.results.retention.enabled() ? "" : ", retention off (nothing deleted)"));
  set_state(DaemonState::starting, "opening devices");

  using clock = std::chrono::steady_clock;
  const auto interval = opts_.check_interval;
  auto next_check = clock::now();
  const auto sched = std::chrono::duration_cast<clock::duration>(
      std::chrono::duration<double>(opts_.schedule_interval_s));
  auto next_schedule = clock::now() + sched;
  auto next_status = clock::now();
  std::uint32_t fails = 0;

  while (!stop_.load()) {
    const auto now = clock::now();
    ping_watchdog(monotonic_ns());

    if (worker_.joinable() && worker_state_->done.load()) {
      const std::uint64_t id = ctx_ ? ctx_->scan_id() : 0;
      finish_scan(false);
      next_check = now + interval;
      // Writing the files is part of the scan: a tick that fell meanwhile (fsync on a loaded
      // disk can take seconds) is refused like one during the run, not made up right after.
      const auto written = clock::now();
      if (sched.count() > 0 && written >= next_schedule) {
        while (next_schedule <= written)
          next_schedule += sched;
        log(kWarning, "trigger from schedule refused: scan " + std::to_string(id) +
                          " was writing its files (not made up)");
      }
    }
    if (reload_.load() && !worker_.joinable()) {
      reload_deferred_logged_ = false;
      do_reload();
    } else if (reload_.load() && !reload_deferred_logged_) {
      reload_deferred_logged_ = true;
      const std::string m = "SIGHUP: reload deferred until scan " +
                            std::to_string(ctx_ ? ctx_->scan_id() : 0) + " ends (not dropped)";
      log(kInfo, m);
      notify_.status("scanning: " + m);
    }

    // Schedule tick: an ordinary trigger, so while a scan runs (or in fault) it is refused with
    // its reason and skipped; ticks missed meanwhile are not made up (no back-to-back scans).
    if (sched.count() > 0 && now >= next_schedule) {
      while (next_schedule <= now)
        next_schedule += sched;
      trigger(TriggerSource::schedule);
    }

    DaemonState st;
    {
      std::lock_guard<std::mutex> lock(mu_);
      st = status_.state;
    }
    if (st == DaemonState::starting || st == DaemonState::fault) {
      if (now >= next_check) {
        next_check = now + interval;
        std::string why;
        bool ok = false;
        if (!backend_open_) {
          ok = try_open();
        } else {
          ok = backend_->check(&why);
          if (!ok) set_state(DaemonState::fault, "devices do not answer: " + why);
        }
        if (ok) {
          // Cleared before the state says idle: a trigger that sees idle is never dropped.
          pending_.store(false);
          set_state(DaemonState::idle,
                    st == DaemonState::starting ? "devices answer, ready" : "devices answer again");
          fails = 0;
        }
        // Up and reporting, whether the devices answer or not (see the header): a machine
        // powered off at boot is a fault the service reports and leaves, not a start timeout.
        if (!ready_sent_) {
          notify_.ready();
          ready_sent_ = true;
          if (!ok)
            log(kWarning,
                "ready, in fault until the devices answer (register map and STATUS= "
                "report it)");
        }
      }
    } else if (st == DaemonState::idle) {
      if (pending_.load()) {
        TriggerSource src;
        {
          std::lock_guard<std::mutex> lock(mu_);
          src = pending_source_;
        }
        start_scan(src);
      } else if (now >= next_check) {
        next_check = now + interval;
        std::string why;
        if (!backend_->check(&why)) {
          // Two failed checks in a row: one lost request is not a fault.
          if (++fails >= 2) set_state(DaemonState::fault, "devices do not answer: " + why);
        } else {
          fails = 0;
        }
      }
    } else if (st == DaemonState::scanning) {
      // No device checks during a scan (the scan is the check); keeps the wait below from
      // collapsing onto a stale check time and polling every millisecond.
      next_check = std::max(next_check, now + interval);
      if (now >= next_status) {
        next_status = now + std::chrono::seconds(1);
        const DaemonStatus s = status();
        notify_.status("scanning: scan " + std::to_string(s.scan_id) + ", " +
                       std::to_string(s.points_done) + "/" + std::to_string(s.points_total) +
                       " points");
      }
      if (worker_.joinable() && !worker_state_->done.load() && now >= next_checkpoint_)
        write_checkpoint();
    }

    // Sleep until woken (signal, trigger, end of scan) or the next periodic duty.
    auto until = next_check;
    if (sched.count() > 0) until = std::min(until, next_schedule);
    if (worker_.joinable()) until = std::min({until, next_status, next_checkpoint_});
    auto wait = std::chrono::duration_cast<std::chrono::milliseconds>(until - clock::now());
    const auto wd = notify_.watchdog_interval();
    if (wd.count() > 0)
      wait = std::min(wait, std::chrono::duration_cast<std::chrono::milliseconds>(wd / 4));
    wait = std::clamp(wait, std::chrono::milliseconds(1), std::chrono::milliseconds(1000));
    pollfd pfd{wake_pipe_[0], POLLIN, 0};
    if (!stop_.load() && !(worker_.joinable() && worker_state_->done.load()) &&
        !(pending_.load() && st == DaemonState::idle))
      ::poll(&pfd, 1, static_cast<int>(wait.count()));
    char buf[64];
    while (::read(wake_pipe_[0], buf, sizeof buf) > 0) {
    }
  }

  // --- stopping: abort the scan, stop the stages, write what was measured, exit in bound.
  // Everything that talks to a device runs against one deadline; a device that does not answer
  // in time is left behind (the process exits next) rather than holding the exit up by a
  // response timeout per stage.  The main thread never calls into the backend while the scan
  // worker may (a device connection serves one thread): the worker stops the stages itself.
  const auto deadline = clock::now() + opts_.stop_timeout;
  set_state(DaemonState::stopping, "SIGTERM");
  notify_.stopping();
  // No more edges: the watcher notices within its 100 ms wait slice.
  gpio_stop_.store(true);
  int rc = 0;
  bool backend_free = true;  // no thread of ours is inside the backend
  if (worker_.joinable()) {
    abort_.store(true);
    while (!worker_state_->done.load() && clock::now() < deadline) {
      pollfd pfd{wake_pipe_[0], POLLIN, 0};
      ::poll(&pfd, 1, 20);
      char buf[64];
      while (::read(wake_pipe_[0], buf, sizeof buf) > 0) {
      }
    }
    if (worker_state_->done.load()) {
      finish_scan(true);
    } else {
      // The worker hangs in a device call: write what it measured and leave it behind.
      log(kErr, "scan worker did not stop within " + std::to_string(opts_.stop_timeout.count()) +
                    " ms; writing the raw data measured so far (the stages got no stop command "
                    "from the daemon: the hung worker holds the devices)");
      set_lamp(false);
      const ScanEnd stopped{ScanOutcome::stopped, "SIGTERM; worker did not stop in time"};
      std::visit([&](const auto& raw) { write_scan_files(raw, stopped); }, ctx_->snapshot());
      worker_.detach();
      worker_left_behind_ = true;
      backend_free = false;
      // Still used by the detached worker: leaked on purpose (the process exits next), and told
      // to LeakSanitizer so a sanitizer run reports only leaks nobody meant.
      auto* ctx = ctx_.release();
#if defined(__SANITIZE_ADDRESS__)
      __lsan_ignore_object(ctx);
#endif
      (void)ctx;
      rc = 2;
    }
  }
  stop_gpio_watch();  // before its backend (which owns the DigitalIo) goes
  if (backend_ && backend_free) {
    // A last stop command to every stage and the devices' close, on a thread of their own so
    // that the deadline holds when a device does not answer.
    auto done = std::make_shared<std::atomic<bool>>(false);
    ScanBackend* be = backend_.release();
#if defined(__SANITIZE_ADDRESS__)
    __lsan_ignore_object(be);  // a closer left behind still holds it when the process exits
#endif
    std::thread closer([be, done] {
      be->stop_motion();
      delete be;
      done->store(true);
    });
    while (!done->load() && clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    if (done->load()) {
      closer.join();
    } else {
      closer.detach();
      log(kWarning, "devices did not take the stop command and close within " +
                        std::to_string(opts_.stop_timeout.count()) + " ms: left behind");
    }
  } else if (backend_) {
    auto* be = backend_.release();  // in use by the worker left behind
#if defined(__SANITIZE_ADDRESS__)
    __lsan_ignore_object(be);
#endif
    (void)be;
  }
  log(kInfo, "stopped");
  return rc;
}

}  // namespace errsep::acq

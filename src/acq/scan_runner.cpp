#include "errsep/acq/scan_runner.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <ctime>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <thread>
#include "errsep/io/machine_axes_metadata.hpp"

#include "errsep/io/plausibility.hpp"
#include "errsep/io/utc_time.hpp"

namespace errsep::acq {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string fmt(double v, int prec = 6) {
  std::ostringstream os;
  os.precision(prec);
  os << v;
  return os.str();
}

/// Thrown inside the runner only, to unwind to the single place that stops the stages.
struct ScanStop {
  ScanRunOutcome outcome;
  std::string reason;
};

class Runner {
 public:
  Runner(const ScanDevices& dev, const ScanOptions& opts, const ScanHooks& hooks)
      : dev_(dev), opts_(opts), hooks_(hooks), averager_(dev.sensors.size()) {}

  ScanResult run();

 private:
  bool aborted() const { return hooks_.abort && hooks_.abort->load(std::memory_order_acquire); }
  void check_abort() const {
    if (aborted()) throw ScanStop{ScanRunOutcome::aborted, "aborted by user (SIGINT/SIGTERM)"};
  }
  void sleep_checking_abort(std::chrono::milliseconds d) const;
  void move(Stage& stage, double pos_mm, const std::string& where);
  /// Averages K readings of the given channels; returns means and mean times (ns).
  WindowAverager::Window measure(const std::vector<std::size_t>& channels,
                                 const std::string& where);
  void four_sensor_single();
  void four_sensor_sequence();
  void four_sensor_fixed();
  void displacement();
  void progress(const std::string& phase, double x_mm, std::vector<double> values);
  void cell(std::size_t column, std::size_t n, double value_um, double t_s) const noexcept;
  void heartbeat() const noexcept;
  double t_rel_s(double t_ns) const { return (t_ns - static_cast<double>(t0_ns_)) * 1e-9; }

  const ScanDevices& dev_;
  const ScanOptions& opts_;
  const ScanHooks& hooks_;
  WindowAverager averager_;
  std::int64_t t0_ns_ = 0;
  double slowest_rate_hz_ = 0.0;  ///< of the buses' samplers: sets the window time-out
  ScanResult res_;
};

void Runner::cell(std::size_t column, std::size_t n, double value_um, double t_s) const noexcept {
  if (!hooks_.cell) return;
  try {
    hooks_.cell(column, n, value_um, t_s);
  } catch (...) {  // the record in res_ is the scan's; a caller's copy must not stop it
  }
}

void Runner::heartbeat() const noexcept {
  if (!hooks_.heartbeat) return;
  try {
    hooks_.heartbeat();
  } catch (...) {
  }
}

void Runner::sleep_checking_abort(std::chrono::milliseconds d) const {
  const auto until = std::chrono::steady_clock::now() + d;
  while (std::chrono::steady_clock::now() < until) {
    check_abort();
    heartbeat();
    std::this_thread::sleep_for(std::min<std::chrono::steady_clock::duration>(
        until - std::chrono::steady_clock::now(), std::chrono::milliseconds(10)));
  }
}

void Runner::move(Stage& stage, double pos_mm, const std::string& where) {
  check_abort();
  const std::string what =
      "stage '" + stage.name() + "': move to " + fmt(pos_mm) + " mm (" + where + ")";
  // A link that drops (IoStatus::disconnected) is reconnected by the bus supervisor
  // (drivers/modbus_bus.hpp) within its back-off, and a loaded PC can leave a command
  // unanswered (IoStatus::timeout) or miss enough answers to make the link drop.  The drive keeps
  // its commanded target meanwhile, so the move waits within its own deadline and commands the
  // target again (an absolute position: the same command twice moves nowhere else) in case the
  // first was lost.  Each such wait is counted (ScanCounts::stage_link_waits); a link that stays
  // down fails the scan at the deadline, naming it.
  bool command_pending = true;
  IoStatus last = IoStatus::ok;
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::milliseconds(opts_.move_timeout_ms);
  for (;;) {
    check_abort();
    bool unanswered = false;
    if (command_pending) {
      last = stage.move_to(pos_mm);
      if (last == IoStatus::ok)
        command_pending = false;
      else if (last == IoStatus::disconnected || last == IoStatus::timeout)
        unanswered = true;
      else
        throw ScanStop{ScanRunOutcome::failed, what + ": command failed: " + to_string(last)};
    }
    if (!command_pending) {
      // Wait in slices so Ctrl-C is honoured within ~100 ms even during a long move.
      last = stage.wait_in_position(std::chrono::milliseconds(100));
      heartbeat();
      if (last == IoStatus::ok) return;
      if (last == IoStatus::fault) {
        unsigned code = 0;
        const IoStatus fs = stage.fault_code(code);
        std::ostringstream os;
        os << what << ": drive fault";
        if (fs == IoStatus::ok) os << " (fault code 0x" << std::hex << code << ")";
        throw ScanStop{ScanRunOutcome::failed, os.str()};
      }
      if (last == IoStatus::disconnected) {
        command_pending = unanswered = true;
      } else if (last != IoStatus::timeout) {  // timeout: still moving
        throw ScanStop{ScanRunOutcome::failed,
                       what + ": waiting for in-position: " + to_string(last)};
      }
    }
    if (unanswered) {
      ++res_.counts.stage_link_waits;
      heartbeat();
      // A timeout has waited already; a link that is down answers at once.
      if (last == IoStatus::disconnected) sleep_checking_abort(std::chrono::milliseconds(100));
    }
    if (std::chrono::steady_clock::now() >= deadline)
      throw ScanStop{ScanRunOutcome::failed,
                     what + ": not in position after " + std::to_string(opts_.move_timeout_ms) +
                         " ms" +
                         (!unanswered                      ? ""
                          : last == IoStatus::disconnected ? " (link down)"
                                                           : " (command unanswered)")};
  }
}

WindowAverager::Window Runner::measure(const std::vector<std::size_t>& channels,
                                       const std::string& where) {
  sleep_checking_abort(std::chrono::milliseconds(opts_.settle_ms));
  const auto k = static_cast<std::uint64_t>(opts_.averages);
  for (int attempt = 0;; ++attempt) {
    check_abort();
    averager_.open(monotonic_ns(), k);
    auto w = averager_.wait(opts_.window_timeout(slowest_rate_hz_),
                            static_cast<std::uint64_t>(opts_.max_errors_per_point), hooks_.abort);
    check_abort();
    bool ok = true;
    for (std::size_t c : channels)
      ok = ok && w.n_ok[c] >= k;
    if (ok) {
      for (std::size_t c : channels)
        res_.counts.samples_averaged += w.n_ok[c];
      return w;
    }
    // Which sensor failed, and how.
    std::size_t worst = channels.front();
    for (std::size_t c : channels)
      if (w.n_ok[c] < k && (w.n_errors[c] > w.n_errors[worst] || w.n_ok[worst] >= k)) worst = c;
    std::ostringstream os;
    os << "sensor '" << dev_.sensors[worst]->name() << "' at " << where << ": " << w.n_ok[worst]
       << " of " << k << " readings ok, " << w.n_errors[worst] << " failed";
    if (w.n_errors[worst] > 0)
      os << " (last: " << to_string(w.last_error) << ")";
    else
      os << " (no readings arrived within " << opts_.window_timeout(slowest_rate_hz_).count()
         << " ms)";
    if (attempt >= opts_.point_retries) {
      os << ", after " << opts_.point_retries << " retries";
      throw ScanStop{ScanRunOutcome::failed, os.str()};
    }
    ++res_.counts.point_retries;
  }
}

void Runner::progress(const std::string& phase, double x_mm, std::vector<double> values) {
  ++res_.counts.points_done;
  heartbeat();
  if (!hooks_.progress) return;
  ScanProgress p;
  p.phase = phase;
  p.point = res_.counts.points_done;
  p.points_total = res_.counts.points_total;
  p.x_mm = x_mm;
  p.values_um = std::move(values);
  try {
    hooks_.progress(p);
  } catch (...) {  // a display problem must not lose a scan
  }
}

// One sensor moved to the four configurations by the sensor stage; a full slide pass for each,
// always in the same direction (no reversal backlash in the data).
void Runner::four_sensor_single() {
  if (opts_.plan != core::ScanSequenceKind::single) return four_sensor_sequence();
  auto& raw = *res_.four_sensor;
  const auto off = opts_.geometry.offsets_mm();
  const int P = opts_.geometry.positions();
  for (int i = 0; i < 4; ++i) {
    const std::string phase = "configuration " + std::to_string(i + 1) + "/4";
    move(*dev_.sensor_stage, opts_.sensor_stage_origin_mm + off[static_cast<std::size_t>(i)],
         phase);
    for (int n = 0; n < P; ++n) {
      const double x = n * opts_.geometry.dx_mm;
      const std::string where = phase + ", x = " + fmt(x) + " mm";
      move(*dev_.slide, opts_.slide_start_mm + opts_.axes.scan_direction * x, where);
      const auto w = measure({0}, where);
      const auto col = static_cast<std::size_t>(i), nn = static_cast<std::size_t>(n);
      raw.m_um[col][nn] = w.mean[0];
      (*raw.t_s)[col][nn] = t_rel_s(w.t_mean_ns[0]);
      cell(col, nn, raw.m_um[col][nn], (*raw.t_s)[col][nn]);
      progress(phase, x, {w.mean[0]});
    }
  }
}

// The traverses of a scan plan (core/scan_sequence.hpp) in their order: the sensor stage to the
// traverse's configuration, the slide through the positions forward or backward.  Each reading
// goes into its traverse's column with its time; the first traverse of each configuration also
// into m1..m4 (and the cell hook, so a checkpoint keeps a separable single scan).  The recorded
// start of a traverse is the time of its first reading.
void Runner::four_sensor_sequence() {
  auto& raw = *res_.four_sensor;
  const auto off = opts_.geometry.offsets_mm();
  const int P = opts_.geometry.positions();
  auto& q = *raw.sequence;
  std::array<bool, 4> seen{};
  for (std::size_t k = 0; k < q.traverses.size(); ++k) {
    auto& tr = q.traverses[k];
    const auto c = static_cast<std::size_t>(tr.configuration);
    const bool first = !seen[c];
    seen[c] = true;
    const bool fwd = tr.direction == core::TraverseDirection::forward;
    const std::string phase = "traverse " + std::to_string(k + 1) + "/" +
                              std::to_string(q.traverses.size()) + " (configuration " +
                              std::to_string(c + 1) + (fwd ? ", forward)" : ", backward)");
    move(*dev_.sensor_stage, opts_.sensor_stage_origin_mm + off[c], phase);
    for (int i = 0; i < P; ++i) {
      const int n = fwd ? i : P - 1 - i;
      const double x = n * opts_.geometry.dx_mm;
      const std::string where = phase + ", x = " + fmt(x) + " mm";
      move(*dev_.slide, opts_.slide_start_mm + opts_.axes.scan_direction * x, where);
      const auto w = measure({0}, where);
      const auto nn = static_cast<std::size_t>(n);
      q.m_um[k][nn] = w.mean[0];
      q.t_s[k][nn] = t_rel_s(w.t_mean_ns[0]);
      if (i == 0) tr.start_s = q.t_s[k][nn];
      if (first) {
        raw.m_um[c][nn] = q.m_um[k][nn];
        (*raw.t_s)[c][nn] = q.t_s[k][nn];
        cell(c, nn, raw.m_um[c][nn], (*raw.t_s)[c][nn]);
      }
      progress(phase, x, {w.mean[0]});
    }
  }
}

// Four sensors at the four configuration offsets, read together at each slide position.
void Runner::four_sensor_fixed() {
  auto& raw = *res_.four_sensor;
  const int P = opts_.geometry.positions();
  for (int n = 0; n < P; ++n) {
    const double x = n * opts_.geometry.dx_mm;
    const std::string where = "x = " + fmt(x) + " mm";
    move(*dev_.slide, opts_.slide_start_mm + opts_.axes.scan_direction * x, where);
    const auto w = measure({0, 1, 2, 3}, where);
    for (std::size_t i = 0; i < 4; ++i) {
      const auto nn = static_cast<std::size_t>(n);
      raw.m_um[i][nn] = w.mean[i];
      (*raw.t_s)[i][nn] = t_rel_s(w.t_mean_ns[i]);
      cell(i, nn, raw.m_um[i][nn], (*raw.t_s)[i][nn]);
    }
    progress("four sensors", x, w.mean);
  }
}

// Haramiishi 2024 section 2.1: pass 1 with the reference piece at its origin (Eqs. 1-2), pass 2
// with it displaced by d (Eq. 3), in the order ScanOptions::scan2_order asks (backward: from the
// last point back, so that a linear drift of sensor 1 shows in its repeat; issue 16 item 4).
// Sensor 0 = workpiece (S1), sensor 1 = reference piece (S2).  Cells are kept by position.
void Runner::displacement() {
  auto& raw = *res_.displacement;
  const int K = opts_.displacement_points;
  for (int pass = 0; pass < 2; ++pass) {
    const std::string phase = "scan " + std::to_string(pass + 1) + "/2";
    move(*dev_.reference_stage, opts_.reference_origin_mm + (pass == 0 ? 0.0 : opts_.d_mm),
         phase + ", reference piece");
    const bool backward = pass == 1 && opts_.scan2_order == core::DisplacementScanOrder::backward;
    for (int i = 0; i < K; ++i) {
      const int k = backward ? K - 1 - i : i;
      const double x = k * opts_.d_mm;
      const std::string where = phase + ", x = " + fmt(x) + " mm";
      move(*dev_.slide, opts_.slide_start_mm + opts_.axes.scan_direction * x, where);
      const auto w = measure({0, 1}, where);
      const auto kk = static_cast<std::size_t>(k);
      (pass == 0 ? raw.s1_scan1_um : raw.s1_scan2_um)[kk] = w.mean[0];
      (pass == 0 ? raw.s2_scan1_um : raw.s2_scan2_um)[kk] = w.mean[1];
      const double t = t_rel_s(0.5 * (w.t_mean_ns[0] + w.t_mean_ns[1]));
      (pass == 0 ? *raw.t_scan1_s : *raw.t_scan2_s)[kk] = t;
      const auto col0 = static_cast<std::size_t>(2 * pass);
      cell(col0, kk, w.mean[0], t);
      cell(col0 + 1, kk, w.mean[1], t);
      progress(phase, x, {w.mean[0], w.mean[1]});
    }
  }
}

ScanResult Runner::run() {
  res_.kind = opts_.kind;
  res_.started_utc = io::utc_now_iso();
  t0_ns_ = monotonic_ns();
  const std::size_t ns = dev_.sensors.size();

  // Prepare the raw record, every cell nan until measured.
  if (opts_.kind == ScanKind::four_sensor) {
    const auto P = static_cast<std::size_t>(opts_.geometry.positions());
    io::RawFourSensorScan raw;
    raw.geometry = opts_.geometry;
    for (std::size_t n = 0; n < P; ++n)
      raw.x_mm.push_back(static_cast<double>(n) * opts_.geometry.dx_mm);
    raw.t_s.emplace();
    for (std::size_t i = 0; i < 4; ++i) {
      raw.m_um[i].assign(P, kNaN);
      (*raw.t_s)[i].assign(P, kNaN);
    }
    std::size_t traverses = 4;
    if (opts_.plan != core::ScanSequenceKind::single) {
      const auto seq = core::ScanSequence::make(opts_.plan, opts_.geometry);
      io::RawSequence q;
      q.plan = seq.name;
      q.traverses = seq.traverses;  // start_s replaced by the measured start
      for (auto& tr : q.traverses)
        tr.start_s = kNaN;
      q.m_um.assign(seq.traverses.size(), std::vector<double>(P, kNaN));
      q.t_s.assign(seq.traverses.size(), std::vector<double>(P, kNaN));
      traverses = seq.traverses.size();
      raw.sequence = std::move(q);
    }
    res_.four_sensor = std::move(raw);
    res_.counts.points_total = static_cast<int>(P * traverses) / (ns == 4 ? 4 : 1);
  } else {
    const auto K = static_cast<std::size_t>(opts_.displacement_points);
    io::RawDisplacementScan raw;
    raw.d_mm = opts_.d_mm;
    raw.scan2_order = opts_.scan2_order;
    for (std::size_t k = 0; k < K; ++k)
      raw.x_mm.push_back(static_cast<double>(k) * opts_.d_mm);
    for (auto* v : {&raw.s1_scan1_um, &raw.s2_scan1_um, &raw.s1_scan2_um, &raw.s2_scan2_um})
      v->assign(K, kNaN);
    raw.t_scan1_s.emplace(K, kNaN);
    raw.t_scan2_s.emplace(K, kNaN);
    res_.displacement = std::move(raw);
    res_.counts.points_total = static_cast<int>(K) * 2;
  }

  // One ring and one sampling thread per bus; one consumer drains them all into the averager.
  std::vector<std::size_t> bus_of = dev_.sensor_bus;
  if (bus_of.empty()) bus_of.assign(ns, 0);
  std::vector<std::size_t> buses = bus_of;
  std::sort(buses.begin(), buses.end());
  buses.erase(std::unique(buses.begin(), buses.end()), buses.end());
  std::vector<std::unique_ptr<SpscRing<Sample>>> rings;
  std::vector<std::unique_ptr<Sampler>> samplers;
  std::vector<SpscRing<Sample>*> ring_ptrs;
  std::vector<double> bus_rate_hz;  // of each sampler
  for (std::size_t b : buses) {
    std::vector<DisplacementSensor*> sensors;
    std::vector<std::uint16_t> channels;
    for (std::size_t i = 0; i < ns; ++i)
      if (bus_of[i] == b) {
        sensors.push_back(dev_.sensors[i]);
        channels.push_back(static_cast<std::uint16_t>(i));
      }
    rings.push_back(std::make_unique<SpscRing<Sample>>(opts_.ring_capacity));
    ring_ptrs.push_back(rings.back().get());
    SamplerOptions so = opts_.sampler;
    if (b < dev_.bus_rate_hz.size() && dev_.bus_rate_hz[b] > 0.0) so.rate_hz = dev_.bus_rate_hz[b];
    bus_rate_hz.push_back(so.rate_hz);
    slowest_rate_hz_ = slowest_rate_hz_ > 0.0 ? std::min(slowest_rate_hz_, so.rate_hz) : so.rate_hz;
    samplers.push_back(std::make_unique<Sampler>(sensors, *rings.back(), so, std::move(channels)));
  }
  RingConsumer consumer(ring_ptrs, [this](const Sample& s) { averager_.add(s); });
  consumer.start();
  for (auto& s : samplers)
    s->start();

  try {
    if (opts_.kind == ScanKind::displacement)
      displacement();
    else if (ns == 1)
      four_sensor_single();
    else
      four_sensor_fixed();
    res_.outcome = ScanRunOutcome::complete;
  } catch (const ScanStop& stop) {
    res_.outcome = stop.outcome;
    res_.stop_reason = stop.reason;
  } catch (const std::exception& e) {  // a driver that throws from a command: still stop safely
    res_.outcome = ScanRunOutcome::failed;
    res_.stop_reason = std::string("unexpected error: ") + e.what();
  }
  if (res_.outcome != ScanRunOutcome::complete)
    for (Stage* st : {dev_.slide, dev_.sensor_stage, dev_.reference_stage})
      if (st) (void)st->stop();

  for (auto& s : samplers)
    s->stop();
  consumer.stop();
  for (auto& s : samplers) {
    res_.samplers.push_back(s->stats());
    const auto& st = res_.samplers.back();
    res_.counts.samples += st.samples_pushed;
    res_.counts.periods += st.periods;
    res_.counts.missed_periods += st.missed_periods;
    res_.counts.overruns += st.overruns;
    res_.counts.read_errors += st.read_errors();
    for (std::size_t i = 0; i < kIoStatusCount; ++i)
      res_.counts.reads_by_status[i] += st.reads_by_status[i];
  }
  res_.counts.samples_consumed = consumer.consumed();
  res_.finished_utc = io::utc_now_iso();
  res_.duration_s = static_cast<double>(monotonic_ns() - t0_ns_) * 1e-9;

  // Metadata of the raw file: what was done, how, and every counter.
  std::vector<std::pair<std::string, std::string>> md;
  md.emplace_back("method", to_string(opts_.kind));
  md.emplace_back("outcome", to_string(res_.outcome));
  md.emplace_back("stop_reason", res_.stop_reason.empty() ? "none" : res_.stop_reason);
  md.emplace_back("started_utc", res_.started_utc);
  md.emplace_back("finished_utc", res_.finished_utc);
  md.emplace_back("duration_s", fmt(res_.duration_s));
  std::string names;
  for (auto* s : dev_.sensors)
    names += (names.empty() ? "" : " ") + s->name();
  md.emplace_back("sensors", names);
  md.insert(md.end(), opts_.range_metadata.begin(), opts_.range_metadata.end());
  // Where the scan ran, in machine coordinates (io/machine_axes_metadata.hpp).
  core::MachineAxes axes = opts_.axes;
  axes.slide_start_mm = opts_.slide_start_mm;
  for (auto& kv : io::machine_axes_metadata(axes))
    md.push_back(std::move(kv));
  if (opts_.kind == ScanKind::four_sensor) {
    md.emplace_back("setup", ns == 1 ? "one sensor on a sensor stage" : "four sensors");
    md.emplace_back("sensor_stage_origin_mm", fmt(opts_.sensor_stage_origin_mm));
  } else {
    md.emplace_back("sample_interval_mm", fmt(opts_.d_mm));
  }
  md.emplace_back("samples_per_point", std::to_string(opts_.averages));
  md.emplace_back("settle_ms", std::to_string(opts_.settle_ms));
  md.emplace_back("sample_rate_hz", fmt(opts_.sampler.rate_hz));
  md.emplace_back("points", std::to_string(res_.counts.points_done) + " of " +
                                std::to_string(res_.counts.points_total));
  md.emplace_back("samples", std::to_string(res_.counts.samples));
  md.emplace_back("samples_consumed", std::to_string(res_.counts.samples_consumed));
  md.emplace_back("samples_averaged", std::to_string(res_.counts.samples_averaged));
  md.emplace_back("periods", std::to_string(res_.counts.periods));
  md.emplace_back("missed_periods", std::to_string(res_.counts.missed_periods));
  md.emplace_back("overruns", std::to_string(res_.counts.overruns));
  md.emplace_back("read_errors", std::to_string(res_.counts.read_errors));
  for (std::size_t i = 1; i < kIoStatusCount; ++i)
    if (res_.counts.reads_by_status[i])
      md.emplace_back(std::string("read_errors_") + to_string(static_cast<IoStatus>(i)),
                      std::to_string(res_.counts.reads_by_status[i]));
  md.emplace_back("retries", std::to_string(res_.counts.point_retries));
  for (std::size_t b = 0; b < res_.samplers.size(); ++b) {
    const auto& j = res_.samplers[b].jitter;
    md.emplace_back("jitter_us_bus" + std::to_string(b),
                    "p50 " + fmt(j.p50_us) + ", p99 " + fmt(j.p99_us) + ", max " + fmt(j.max_us));
    md.emplace_back("realtime_bus" + std::to_string(b), res_.samplers[b].realtime.brief());
    if (bus_rate_hz[b] != opts_.sampler.rate_hz)
      md.emplace_back("sample_rate_hz_bus" + std::to_string(b), fmt(bus_rate_hz[b]));
  }
  if (res_.four_sensor) {
    res_.four_sensor->complete = res_.complete();
    res_.four_sensor->metadata = md;
  } else {
    res_.displacement->complete = res_.complete();
    res_.displacement->metadata = md;
  }
  return std::move(res_);
}

}  // namespace

const char* to_string(ScanKind k) noexcept {
  return k == ScanKind::four_sensor ? "four_sensor" : "displacement";
}

const char* to_string(ScanRunOutcome o) noexcept {
  switch (o) {
    case ScanRunOutcome::complete:
      return "complete";
    case ScanRunOutcome::aborted:
      return "aborted";
    case ScanRunOutcome::failed:
      return "failed";
  }
  return "unknown";
}

std::chrono::milliseconds ScanOptions::window_timeout(double rate_hz) const {
  const double rate = rate_hz > 0.0 ? rate_hz : sampler.rate_hz;
  return std::chrono::milliseconds(static_cast<long>(std::ceil(4.0 * averages * 1000.0 / rate)) +
                                   1000);
}

bool ScanOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (kind == ScanKind::four_sensor && !geometry.is_valid(why)) return false;
  // The rezeroed plan's second pass needs the sensor moved in its holder by a stated offset: a
  // step by hand that no stage here performs, and the runner has no pause for an operator.
  if (kind == ScanKind::four_sensor && plan == core::ScanSequenceKind::rezeroed)
    return fail(
        "scan.plan = rezeroed: the second pass needs the sensor re-zeroed by hand (moved in its "
        "holder by a stated offset), which the scan runner cannot do or pause for; measure it "
        "as two scans (plan single) and join them with the offset recorded, or simulate it "
        "(errsep-simulate --plan rezeroed)");
  if (averages < 1) return fail("scan.averages = " + std::to_string(averages) + ": must be >= 1");
  if (settle_ms < 0)
    return fail("scan.settle_ms = " + std::to_string(settle_ms) + ": must be >= 0");
  if (kind == ScanKind::displacement) {
    if (!(d_mm > 0) || !std::isfinite(d_mm))
      return fail("scan.d_mm = " + fmt(d_mm) + ": must be > 0");
    if (displacement_points < 2)
      return fail("scan.displacement_points = " + std::to_string(displacement_points) +
                  ": must be >= 2");
  }
  if (move_timeout_ms < 1)
    return fail("move_timeout_ms = " + std::to_string(move_timeout_ms) + ": must be >= 1");
  if (max_errors_per_point < 0)
    return fail("max_errors_per_point = " + std::to_string(max_errors_per_point) +
                ": must be >= 0");
  if (point_retries < 0)
    return fail("point_retries = " + std::to_string(point_retries) + ": must be >= 0");
  if (ring_capacity < 16)
    return fail("ring_capacity = " + std::to_string(ring_capacity) + ": must be >= 16");
  return sampler.is_valid(why);
}

std::vector<std::pair<std::string, std::string>> sensor_range_metadata(const io::MachineConfig& cfg,
                                                                       ScanKind kind) {
  const auto& sc = cfg.scan;
  std::vector<std::pair<std::string, std::string>> md;
  auto add = [&](const std::string& column_sensor, const std::string& name) {
    for (const auto& s : cfg.sensors)
      if (s.name == name) {
        const auto r = io::range_metadata(column_sensor, s.range_min_um, s.range_max_um);
        md.insert(md.end(), r.begin(), r.end());
      }
  };
  if (kind == ScanKind::four_sensor) {
    // One sensor on the sensor stage reads all four configurations; else one per configuration.
    for (std::size_t i = 0; i < 4; ++i)
      if (sc.sensors.size() == 1 || i < sc.sensors.size())
        add("m" + std::to_string(i + 1), sc.sensors[sc.sensors.size() == 1 ? 0 : i]);
  } else {
    add("s1", sc.workpiece_sensor);
    add("s2", sc.reference_sensor);
  }
  return md;
}

ScanOptions scan_options_from_config(const io::MachineConfig& cfg, ScanKind kind) {
  const auto& sc = cfg.scan;
  ScanOptions o;
  o.kind = kind;
  o.geometry = sc.geometry;
  o.slide_start_mm = sc.slide_start_mm;
  o.axes = cfg.axes;
  o.sensor_stage_origin_mm = sc.sensor_stage_origin_mm;
  o.averages = sc.averages;
  o.settle_ms = sc.settle_ms;
  o.plan = sc.plan;
  o.d_mm = sc.d_mm;
  o.displacement_points = sc.displacement_points > 0 ? sc.displacement_points : sc.geometry.N;
  o.scan2_order = sc.scan2_order;
  int timeout = 0;
  for (const auto& st : cfg.stages)
    timeout = std::max(timeout, st.move_timeout_ms);
  o.move_timeout_ms = timeout > 0 ? timeout : o.move_timeout_ms;
  o.sampler.rate_hz = cfg.sampler.rate_hz;
  if (cfg.sampler.realtime) {
    o.sampler.realtime.lock_memory = true;
    o.sampler.realtime.fifo_priority = cfg.sampler.fifo_priority;
  }
  o.sampler.realtime.cpu = cfg.sampler.cpu_affinity;
  o.ring_capacity = cfg.sampler.ring_capacity;
  o.range_metadata = sensor_range_metadata(cfg, kind);
  std::string why;
  if (!o.is_valid(&why)) throw std::invalid_argument(cfg.source.string() + ": [scan]: " + why);
  return o;
}

std::string ScanResult::brief_report() const {
  std::ostringstream os;
  os << to_string(kind) << " scan " << to_string(outcome) << ": " << counts.points_done << "/"
     << counts.points_total << " points, " << counts.samples << " samples ("
     << counts.samples_averaged << " averaged), missed periods " << counts.missed_periods
     << ", overruns " << counts.overruns << ", read errors " << counts.read_errors << ", retries "
     << counts.point_retries;
  if (counts.stage_link_waits > 0)
    os << ", stage link down or unanswered " << counts.stage_link_waits << "x (waited, sent again)";
  for (std::size_t b = 0; b < samplers.size(); ++b)
    os << ", jitter p50/p99/max " << samplers[b].jitter.p50_us << "/" << samplers[b].jitter.p99_us
       << "/" << samplers[b].jitter.max_us << " us";
  os << ", " << fmt(duration_s, 3) << " s";
  if (!stop_reason.empty()) os << "; " << stop_reason;
  return os.str();
}

ScanResult run_scan(const ScanDevices& devices, const ScanOptions& opts, const ScanHooks& hooks) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("run_scan: " + why);
  if (!devices.slide) throw std::invalid_argument("run_scan: no slide stage");
  for (auto* s : devices.sensors)
    if (!s) throw std::invalid_argument("run_scan: null sensor");
  if (!devices.sensor_bus.empty() && devices.sensor_bus.size() != devices.sensors.size())
    throw std::invalid_argument("run_scan: sensor_bus has " +
                                std::to_string(devices.sensor_bus.size()) + " entries for " +
                                std::to_string(devices.sensors.size()) + " sensors");
  if (opts.kind == ScanKind::four_sensor) {
    if (devices.sensors.size() != 1 && devices.sensors.size() != 4)
      throw std::invalid_argument(
          "run_scan: a four-sensor scan needs 1 sensor (on a sensor "
          "stage) or 4 sensors, got " +
          std::to_string(devices.sensors.size()));
    if (devices.sensors.size() == 1 && !devices.sensor_stage)
      throw std::invalid_argument(
          "run_scan: a four-sensor scan with one sensor needs the sensor stage to move it");
    if (devices.sensors.size() != 1 && opts.plan != core::ScanSequenceKind::single)
      throw std::invalid_argument(
          std::string("run_scan: plan '") + core::to_string(opts.plan) +
          "' needs one sensor on the sensor stage (a traverse measures one configuration)");
  } else {
    if (devices.sensors.size() != 2)
      throw std::invalid_argument(
          "run_scan: a displacement scan needs 2 sensors (workpiece, reference piece), got " +
          std::to_string(devices.sensors.size()));
    if (!devices.reference_stage)
      throw std::invalid_argument(
          "run_scan: a displacement scan needs the reference-piece stage to displace it by d");
  }
  Runner r(devices, opts, hooks);
  return r.run();
}

}  // namespace errsep::acq

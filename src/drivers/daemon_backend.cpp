#include "errsep/drivers/daemon_backend.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <thread>

#include "errsep/acq/sampler.hpp"
#include "errsep/acq/scan_runner.hpp"
#include "errsep/io/machine_axes_metadata.hpp"

namespace errsep::drivers {
namespace {

using acq::IoStatus;
using acq::ScanEnd;
using acq::ScanOutcome;

[[noreturn]] void config_error(const io::MachineConfig& cfg, const std::string& key,
                               const std::string& what) {
  throw std::runtime_error(cfg.source.string() + ": " + key + ": " + what);
}

}  // namespace

DeviceScanBackend::DeviceScanBackend(io::MachineConfig cfg) : cfg_(std::move(cfg)) {
  const auto& sc = cfg_.scan;
  if (sc.method != io::ScanMethod::four_sensor)
    config_error(
        cfg_, "scan.method",
        std::string("'") + io::to_string(sc.method) + "': the daemon runs four_sensor scans only");
  std::string why;
  if (!sc.geometry.is_valid(&why)) config_error(cfg_, "scan", why);
  if (sc.geometry.positions() < 2)
    config_error(cfg_, "scan.N", "fewer than 2 slide positions (N - s2 - s3 - s4)");
  const std::size_t need = sc.single_sensor ? 1 : 4;
  if (sc.sensors.size() != need)
    config_error(cfg_, "scan.sensors",
                 std::to_string(sc.sensors.size()) + " names, " + std::to_string(need) + " needed");
  if (!cfg_.find_stage(sc.slide_stage))
    config_error(cfg_, "scan.slide_stage", "no [[stage]] named '" + sc.slide_stage + "'");
  if (sc.single_sensor && !cfg_.find_stage(sc.sensor_stage))
    config_error(cfg_, "scan.sensor_stage", "no [[stage]] named '" + sc.sensor_stage + "'");
  if (sc.averages < 1) config_error(cfg_, "scan.averages", "must be >= 1");
}

DeviceScanBackend::~DeviceScanBackend() {
  if (dev_) dev_->stop_all_stages();
}

void DeviceScanBackend::open() {
  dev_.reset();
  auto d = std::make_unique<Devices>(make_devices(cfg_));
  d->configure();
  dev_ = std::move(d);
}

bool DeviceScanBackend::check(std::string* why) {
  if (!dev_) {
    if (why) *why = "devices not opened";
    return false;
  }
  ModbusStage* slide = dev_->stage(cfg_.scan.slide_stage);
  std::uint16_t bits = 0;
  IoStatus st = slide->status_word(bits);
  if (st != IoStatus::ok) {
    if (why) *why = "stage " + slide->name() + ": " + acq::to_string(st);
    return false;
  }
  if (bits & (1u << slide->config().fault_bit)) {
    if (why) *why = "stage " + slide->name() + ": drive fault";
    return false;
  }
  ModbusSensor* s = dev_->sensor(cfg_.scan.sensors.front());
  std::uint16_t words[4] = {};
  st = s->bus().read(s->config().reg, words);
  if (st != IoStatus::ok) {
    if (why) *why = "sensor " + s->name() + ": " + acq::to_string(st);
    return false;
  }
  return true;
}

void DeviceScanBackend::stop_motion() noexcept {
  if (dev_) dev_->stop_all_stages();
}

acq::StartInput DeviceScanBackend::start_input() {
  acq::StartInput in;
  if (!dev_ || !dev_->gpio || !cfg_.gpio || cfg_.gpio->start_line < 0) return in;
  in.io = dev_->gpio.get();
  in.line = static_cast<unsigned>(cfg_.gpio->start_line);
  in.lamp_line = cfg_.gpio->output_line;
  in.name = cfg_.gpio->chip + " line " + std::to_string(cfg_.gpio->start_line);
  return in;
}

std::string DeviceScanBackend::describe() const {
  std::ostringstream os;
  os << "machine config " << cfg_.source.string() << ": " << cfg_.buses.size() << " buses, "
     << cfg_.sensors.size() << " sensors, " << cfg_.stages.size() << " stages; scan "
     << (cfg_.scan.single_sensor ? "one sensor on the sensor stage" : "four fixed probes")
     << ", N = " << cfg_.scan.geometry.N << ", " << cfg_.scan.geometry.positions()
     << " positions, K = " << cfg_.scan.averages;
  if (cfg_.gpio && cfg_.gpio->start_line >= 0)
    os << "; GPIO start input " << cfg_.gpio->chip << " line " << cfg_.gpio->start_line;
  return os.str();
}

ScanEnd DeviceScanBackend::run_scan(acq::ScanContext& ctx) {
  if (!dev_) return {ScanOutcome::device_fault, "devices not opened"};
  const io::ScanConfig& sc = cfg_.scan;
  const core::FourSensorConfig& g = sc.geometry;
  const auto P = static_cast<std::size_t>(g.positions());
  const std::array<double, 4> off = g.offsets_mm();

  io::RawFourSensorScan layout;
  layout.geometry = g;
  layout.x_mm.resize(P);
  for (std::size_t n = 0; n < P; ++n)
    layout.x_mm[n] = static_cast<double>(n) * g.dx_mm;
  layout.metadata = {{"machine_config", cfg_.source.string()},
                     {"averages", std::to_string(sc.averages)},
                     {"single_sensor", sc.single_sensor ? "true" : "false"}};
  const auto ranges = acq::sensor_range_metadata(cfg_, acq::ScanKind::four_sensor);
  layout.metadata.insert(layout.metadata.end(), ranges.begin(), ranges.end());
  for (auto& kv : io::machine_axes_metadata(cfg_.axes))  // where the scan runs, machine coords
    layout.metadata.push_back(std::move(kv));
  ctx.begin(layout);

  // Channels: scan sensors grouped by bus so that each bus's sampler gets contiguous channels.
  std::vector<std::size_t> scan_idx;  // index into dev_->sensors, per scan sensor
  for (const auto& name : sc.sensors) {
    for (std::size_t i = 0; i < dev_->sensors.size(); ++i)
      if (dev_->sensors[i]->name() == name) scan_idx.push_back(i);
  }
  const std::size_t nch = scan_idx.size();
  std::vector<int> config_of_channel(nch, 0);
  std::vector<std::unique_ptr<acq::SpscRing<acq::Sample>>> rings;
  std::vector<std::unique_ptr<acq::Sampler>> samplers;
  std::uint16_t ch = 0;
  for (std::size_t b = 0; b < dev_->buses.size(); ++b) {
    std::vector<acq::DisplacementSensor*> on_bus;
    for (std::size_t k = 0; k < nch; ++k) {
      if (dev_->sensor_bus[scan_idx[k]] != b) continue;
      on_bus.push_back(dev_->sensors[scan_idx[k]].get());
      config_of_channel[ch + on_bus.size() - 1] = static_cast<int>(k);
    }
    if (on_bus.empty()) continue;
    acq::SamplerOptions so;
    so.rate_hz = cfg_.sample_rate_hz(dev_->buses[b]->config());
    so.channel_base = ch;
    if (cfg_.sampler.realtime) {
      so.realtime.lock_memory = true;
      so.realtime.fifo_priority = cfg_.sampler.fifo_priority;
    }
    so.realtime.cpu = cfg_.sampler.cpu_affinity;
    rings.push_back(std::make_unique<acq::SpscRing<acq::Sample>>(cfg_.sampler.ring_capacity));
    samplers.push_back(std::make_unique<acq::Sampler>(on_bus, *rings.back(), so));
    ch = static_cast<std::uint16_t>(ch + on_bus.size());
  }
  acq::WindowAverager avg(nch);
  std::vector<acq::SpscRing<acq::Sample>*> ring_ptrs;
  for (auto& r : rings)
    ring_ptrs.push_back(r.get());
  acq::RingConsumer consumer(ring_ptrs, [&avg](const acq::Sample& s) { avg.add(s); });
  consumer.start();
  for (auto& s : samplers)
    s->start();
  // Stops the threads on every way out, samplers first so the consumer drains everything.
  struct Stopper {
    std::vector<std::unique_ptr<acq::Sampler>>& s;
    acq::RingConsumer& c;
    ~Stopper() {
      for (auto& x : s)
        x->stop();
      c.stop();
    }
  } stopper{samplers, consumer};

  const std::int64_t t0_ns = acq::monotonic_ns();
  ModbusStage* slide = dev_->stage(sc.slide_stage);
  ModbusStage* sstage = sc.single_sensor ? dev_->stage(sc.sensor_stage) : nullptr;

  auto fail = [&](ScanOutcome o, const std::string& msg) -> ScanEnd {
    dev_->stop_all_stages();
    return {o, msg};
  };
  auto aborted = [&]() -> ScanEnd { return fail(ScanOutcome::aborted, "aborted"); };

  // Moves and waits in slices, so an abort is seen within ~100 ms.
  auto move = [&](ModbusStage* st, double pos_mm, std::string* why) -> IoStatus {
    IoStatus s = st->move_to(pos_mm);
    if (s != IoStatus::ok) {
      *why = "stage " + st->name() + ": move to " + std::to_string(pos_mm) +
             " mm: " + acq::to_string(s);
      return s;
    }
    const auto deadline =
        std::chrono::steady_clock::now() + std::chrono::milliseconds(st->config().move_timeout_ms);
    while (true) {
      if (ctx.abort_requested()) return IoStatus::ok;
      s = st->wait_in_position(std::chrono::milliseconds(100));
      ctx.heartbeat();
      if (s == IoStatus::ok) return s;
      if (s != IoStatus::timeout) {
        unsigned code = 0;
        st->fault_code(code);
        *why = "stage " + st->name() + ": " + acq::to_string(s) +
               (s == IoStatus::fault ? " (fault code " + std::to_string(code) + ")" : "");
        return s;
      }
      if (std::chrono::steady_clock::now() >= deadline) {
        *why = "stage " + st->name() + ": not in position at " + std::to_string(pos_mm) +
               " mm within " + std::to_string(st->config().move_timeout_ms) + " ms";
        return IoStatus::timeout;
      }
    }
  };
  const double rate = samplers.empty() ? cfg_.sampler.rate_hz : samplers.front()->options().rate_hz;
  const auto window_timeout =
      std::chrono::milliseconds(500 + static_cast<long>(3000.0 * sc.averages / rate));
  const auto K = static_cast<std::uint64_t>(sc.averages);

  // Averages the window at the current point; records channel c as configuration
  // config_of_channel[c] (single sensor: `config`).
  auto measure = [&](std::size_t n, int config, std::string* why) -> bool {
    if (sc.settle_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(sc.settle_ms));
    avg.open(acq::monotonic_ns(), K);
    const auto w = avg.wait(window_timeout, K, &ctx.abort_flag());
    if (ctx.abort_requested()) return true;
    if (!w.complete) {
      std::size_t worst = 0;
      for (std::size_t c = 0; c < nch; ++c)
        if (w.n_ok[c] < w.n_ok[worst]) worst = c;
      *why = "sensor " + sc.sensors[static_cast<std::size_t>(config_of_channel[worst])] + ": " +
             std::to_string(w.n_ok[worst]) + "/" + std::to_string(K) + " readings, " +
             std::to_string(w.n_errors[worst]) + " errors (last " + acq::to_string(w.last_error) +
             ")";
      return false;
    }
    for (std::size_t c = 0; c < nch; ++c) {
      const int cfg_i = sc.single_sensor ? config : config_of_channel[c];
      ctx.record(cfg_i, n, w.mean[c], (w.t_mean_ns[c] - static_cast<double>(t0_ns)) * 1e-9);
    }
    return true;
  };

  std::string why;
  const int configs = sc.single_sensor ? 4 : 1;
  for (int i = 0; i < configs; ++i) {
    if (sstage) {
      if (move(sstage, sc.sensor_stage_origin_mm + off[static_cast<std::size_t>(i)], &why) !=
          IoStatus::ok)
        return fail(ScanOutcome::device_fault, why);
    }
    for (std::size_t n = 0; n < P; ++n) {
      if (ctx.abort_requested()) return aborted();
      if (move(slide, sc.slide_start_mm + cfg_.axes.scan_direction * layout.x_mm[n], &why) !=
          IoStatus::ok)
        return fail(ScanOutcome::device_fault, why);
      if (ctx.abort_requested()) return aborted();
      if (!measure(n, i, &why)) return fail(ScanOutcome::device_fault, why);
      if (ctx.abort_requested()) return aborted();
    }
  }
  return {ScanOutcome::complete, {}};
}

}  // namespace errsep::drivers

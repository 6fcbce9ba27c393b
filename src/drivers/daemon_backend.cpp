#include "errsep/drivers/daemon_backend.hpp"

#include <sstream>

#include "errsep/acq/scan_runner.hpp"
#include "errsep/drivers/scan_devices.hpp"
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
  if (sc.method == io::ScanMethod::both)
    config_error(cfg_, "scan.method",
                 "'both': the daemon runs one kind of scan per trigger: four_sensor or "
                 "displacement");
  if (sc.method == io::ScanMethod::displacement) {
    // The scan's devices (sensors, stages) are checked by drivers::scan_devices when it runs;
    // what a scan needs is checked here, at start, with the key that is wrong.
    std::string why;
    if (!acq::scan_options_from_config(cfg_, acq::ScanKind::displacement).is_valid(&why))
      config_error(cfg_, "scan", why);
    for (const auto* name : {&sc.workpiece_sensor, &sc.reference_sensor})
      if (!cfg_.find_sensor(*name))
        config_error(
            cfg_, name == &sc.workpiece_sensor ? "scan.workpiece_sensor" : "scan.reference_sensor",
            "no [[sensor]] named '" + *name + "'");
    for (const auto* name : {&sc.slide_stage, &sc.reference_stage})
      if (!cfg_.find_stage(*name))
        config_error(cfg_, name == &sc.slide_stage ? "scan.slide_stage" : "scan.reference_stage",
                     "no [[stage]] named '" + *name + "'");
    return;
  }
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
  const bool displacement = cfg_.scan.method == io::ScanMethod::displacement;
  ModbusSensor* s =
      dev_->sensor(displacement ? cfg_.scan.workpiece_sensor : cfg_.scan.sensors.front());
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
     << cfg_.sensors.size() << " sensors, " << cfg_.stages.size() << " stages; scan ";
  if (cfg_.scan.method == io::ScanMethod::displacement)
    os << "displacement method (Haramiishi 2024), "
       << acq::scan_options_from_config(cfg_, acq::ScanKind::displacement).displacement_points
       << " positions, d = " << cfg_.scan.d_mm << " mm";
  else
    os << (cfg_.scan.single_sensor ? "one sensor on the sensor stage" : "four fixed probes")
       << ", N = " << cfg_.scan.geometry.N << ", " << cfg_.scan.geometry.positions()
       << " positions";
  os << ", K = " << cfg_.scan.averages;
  if (cfg_.gpio && cfg_.gpio->start_line >= 0)
    os << "; GPIO start input " << cfg_.gpio->chip << " line " << cfg_.gpio->start_line;
  return os.str();
}

ScanEnd DeviceScanBackend::run_scan(acq::ScanContext& ctx) {
  if (!dev_) return {ScanOutcome::device_fault, "devices not opened"};
  // The scan loop is errsep-scan's (acq::run_scan): the same point retries, read-error budget,
  // window time-out and sampler counters.  This is the wiring into the daemon's ScanContext:
  // each measured cell goes there at once, so the main loop's checkpoints keep it.
  const auto kind = cfg_.scan.method == io::ScanMethod::displacement ? acq::ScanKind::displacement
                                                                     : acq::ScanKind::four_sensor;
  const acq::ScanOptions opts = acq::scan_options_from_config(cfg_, kind);
  const acq::ScanDevices devices = scan_devices(*dev_, cfg_, kind);
  const std::vector<std::pair<std::string, std::string>> config_md = {
      {"config", cfg_.source.string()}};

  // What a checkpoint holds before the scan's own record.
  auto layout_metadata = config_md;
  layout_metadata.insert(layout_metadata.end(), opts.range_metadata.begin(),
                         opts.range_metadata.end());
  for (auto& kv : io::machine_axes_metadata(cfg_.axes))  // where the scan runs, machine coords
    layout_metadata.push_back(std::move(kv));
  if (kind == acq::ScanKind::displacement) {
    io::RawDisplacementScan layout;  // positions as acq::run_scan's: x_k = k·d
    layout.d_mm = opts.d_mm;
    layout.scan2_order = opts.scan2_order;  // a checkpoint's times go the way scan 2 ran
    for (int k = 0; k < opts.displacement_points; ++k)
      layout.x_mm.push_back(k * opts.d_mm);
    layout.metadata = layout_metadata;
    ctx.begin(std::move(layout));
  } else {
    io::RawFourSensorScan layout;
    layout.geometry = opts.geometry;
    for (int n = 0; n < opts.geometry.positions(); ++n)
      layout.x_mm.push_back(n * opts.geometry.dx_mm);
    layout.metadata = layout_metadata;
    ctx.begin(std::move(layout));
  }

  acq::ScanHooks hooks;
  hooks.abort = &ctx.abort_flag();
  hooks.cell = [&ctx](std::size_t column, std::size_t n, double value_um, double t_s) {
    ctx.record(static_cast<int>(column), n, value_um, t_s);
  };
  hooks.heartbeat = [&ctx] { ctx.heartbeat(); };
  acq::ScanResult res = acq::run_scan(devices, opts, hooks);
  if (res.four_sensor) {
    res.four_sensor->metadata.insert(res.four_sensor->metadata.begin(), config_md.begin(),
                                     config_md.end());
    ctx.finish(std::move(*res.four_sensor));  // with the sampler's counters
  } else if (res.displacement) {
    res.displacement->metadata.insert(res.displacement->metadata.begin(), config_md.begin(),
                                      config_md.end());
    ctx.finish(std::move(*res.displacement));
  }
  switch (res.outcome) {
    case acq::ScanRunOutcome::complete:
      return {ScanOutcome::complete, {}};
    case acq::ScanRunOutcome::aborted:
      return {ScanOutcome::aborted, "aborted"};
    case acq::ScanRunOutcome::failed:
      break;
  }
  return {ScanOutcome::device_fault, res.stop_reason};
}

}  // namespace errsep::drivers

#include "errsep/drivers/scan_devices.hpp"

#include <stdexcept>

namespace errsep::drivers {
namespace {

std::size_t sensor_index(const io::MachineConfig& cfg, const std::string& name,
                         const std::string& key) {
  for (std::size_t i = 0; i < cfg.sensors.size(); ++i)
    if (cfg.sensors[i].name == name) return i;
  throw std::runtime_error(cfg.source.string() + ": " + key + ": no [[sensor]] named '" + name +
                           "'");
}

acq::Stage* stage(const Devices& dev, const io::MachineConfig& cfg, const std::string& name,
                  const std::string& key) {
  if (name.empty())
    throw std::runtime_error(cfg.source.string() + ": " + key + ": not set (name a [[stage]])");
  auto* s = dev.stage(name);
  if (!s)
    throw std::runtime_error(cfg.source.string() + ": " + key + ": no [[stage]] named '" + name +
                             "'");
  return s;
}

}  // namespace

acq::ScanDevices scan_devices(const Devices& dev, const io::MachineConfig& cfg,
                              acq::ScanKind kind) {
  const auto& sc = cfg.scan;
  acq::ScanDevices d;
  d.slide = stage(dev, cfg, sc.slide_stage, "scan.slide_stage");
  std::vector<std::pair<std::string, std::string>> names;  // name, key
  if (kind == acq::ScanKind::four_sensor) {
    const std::size_t want = sc.single_sensor ? 1 : 4;
    if (sc.sensors.size() != want)
      throw std::runtime_error(
          cfg.source.string() + ": scan.sensors: " + std::to_string(sc.sensors.size()) +
          " names, " + std::to_string(want) +
          " needed with single_sensor = " + (sc.single_sensor ? "true" : "false"));
    for (const auto& n : sc.sensors)
      names.emplace_back(n, "scan.sensors");
    if (sc.single_sensor) d.sensor_stage = stage(dev, cfg, sc.sensor_stage, "scan.sensor_stage");
  } else {
    names.emplace_back(sc.workpiece_sensor, "scan.workpiece_sensor");
    names.emplace_back(sc.reference_sensor, "scan.reference_sensor");
    d.reference_stage = stage(dev, cfg, sc.reference_stage, "scan.reference_stage");
  }
  for (const auto& [name, key] : names) {
    const std::size_t i = sensor_index(cfg, name, key);
    if (i >= dev.sensors.size() || !dev.sensors[i])
      throw std::runtime_error(cfg.source.string() + ": " + key + ": sensor '" + name +
                               "' has no driver");
    d.sensors.push_back(dev.sensors[i].get());
    d.sensor_bus.push_back(dev.sensor_bus[i]);
  }
  for (std::size_t b = 0; b < cfg.buses.size(); ++b)  // Devices::buses is in config order
    d.bus_rate_hz.push_back(cfg.sample_rate_hz(cfg.buses[b]));
  return d;
}

}  // namespace errsep::drivers

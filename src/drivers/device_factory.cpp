#include "errsep/drivers/device_factory.hpp"

#include "errsep/drivers/gpiod_io.hpp"

#include <stdexcept>

namespace errsep::drivers {

Devices::~Devices() {
  if (supervisor) supervisor->stop();
}

Devices make_devices(const io::MachineConfig& cfg, SupervisorOptions supervisor) {
  Devices d;
  for (const auto& b : cfg.buses)
    d.buses.push_back(std::make_unique<ModbusBus>(b));
  auto bus_index = [&](const std::string& name, const std::string& who) {
    for (std::size_t i = 0; i < cfg.buses.size(); ++i)
      if (cfg.buses[i].name == name) return i;
    throw std::runtime_error(who + ": no [[bus]] named '" + name + "'");
  };
  std::vector<std::uint16_t> next_channel(cfg.buses.size(), 0);
  for (const auto& s : cfg.sensors) {
    const std::size_t bi = bus_index(s.bus, "sensor '" + s.name + "'");
    d.sensors.push_back(std::make_unique<ModbusSensor>(s, *d.buses[bi], next_channel[bi]++));
    d.sensor_bus.push_back(bi);
  }
  for (const auto& s : cfg.stages) {
    const std::size_t bi = bus_index(s.bus, "stage '" + s.name + "'");
    d.stages.push_back(std::make_unique<ModbusStage>(s, *d.buses[bi]));
  }
  // ---- GPIO (helper 4b): the libgpiod driver of [gpio]; opened by configure() ---------------
  if (cfg.gpio) d.gpio = std::make_unique<GpiodIo>(*cfg.gpio);  // drivers/gpiod_io.hpp
  // ------------------------------------------------------------------------------------------
  std::vector<ModbusBus*> raw;
  for (auto& b : d.buses)
    raw.push_back(b.get());
  d.supervisor = std::make_unique<BusSupervisor>(std::move(raw), supervisor);
  return d;
}

void Devices::configure() {
  for (auto& b : buses)
    b->configure();
  for (auto& s : sensors)
    s->configure();
  for (auto& s : stages)
    s->configure();
  if (gpio) gpio->configure();
  if (supervisor) supervisor->start();
}

void Devices::stop_all_stages() noexcept {
  for (auto& s : stages)
    s->stop();
}

ModbusBus* Devices::bus(const std::string& name) const {
  for (const auto& b : buses)
    if (b->name() == name) return b.get();
  return nullptr;
}
ModbusSensor* Devices::sensor(const std::string& name) const {
  for (const auto& s : sensors)
    if (s->name() == name) return s.get();
  return nullptr;
}
ModbusStage* Devices::stage(const std::string& name) const {
  for (const auto& s : stages)
    if (s->name() == name) return s.get();
  return nullptr;
}
std::vector<std::size_t> Devices::sensors_on_bus(std::size_t bus_index) const {
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < sensors.size(); ++i)
    if (sensor_bus[i] == bus_index) out.push_back(i);
  return out;
}

}  // namespace errsep::drivers

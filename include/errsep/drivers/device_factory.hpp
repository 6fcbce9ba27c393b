#pragma once
// Builds the drivers a machine config describes: one ModbusBus per [[bus]], one ModbusSensor per
// [[sensor]], one ModbusStage per [[stage]], the bus supervisor, and the GPIO device of [gpio].
//
//   auto dev = drivers::make_devices(cfg);   // constructs only: no I/O, nothing opened
//   dev.configure();                         // opens buses, probes devices, starts supervisor
//   for (auto& s : dev.sensors) ...          // same order as cfg.sensors
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "errsep/acq/digital_io.hpp"
#include "errsep/acq/displacement_sensor.hpp"
#include "errsep/acq/stage.hpp"
#include "errsep/drivers/modbus_bus.hpp"
#include "errsep/drivers/modbus_sensor.hpp"
#include "errsep/drivers/modbus_stage.hpp"
#include "errsep/io/machine_config.hpp"

namespace errsep::drivers {

struct Devices {
  std::vector<std::unique_ptr<ModbusBus>> buses;       ///< same order as cfg.buses
  std::vector<std::unique_ptr<ModbusSensor>> sensors;  ///< same order as cfg.sensors
  std::vector<std::size_t> sensor_bus;                 ///< index into buses, per sensor
  std::vector<std::unique_ptr<ModbusStage>> stages;    ///< same order as cfg.stages
  /// The [gpio] device (libgpiod driver of drivers/gpiod_io.hpp), or null when the config has
  /// no [gpio] section: check before use.
  std::unique_ptr<acq::DigitalIo> gpio;
  std::unique_ptr<BusSupervisor> supervisor;  ///< reconnects buses; started by configure()

  Devices() = default;
  Devices(Devices&&) = default;
  Devices& operator=(Devices&&) = default;
  ~Devices();  ///< stops the supervisor before the buses go

  /// Opens every bus, then configures every sensor, stage and the GPIO device, then starts the
  /// supervisor.  Throws std::runtime_error naming the device that failed.  Not real-time safe.
  void configure();
  /// Stops every stage (best effort, never throws).
  void stop_all_stages() noexcept;

  ModbusBus* bus(const std::string& name) const;
  ModbusSensor* sensor(const std::string& name) const;
  ModbusStage* stage(const std::string& name) const;
  /// Indices (into sensors) of the sensors on buses[bus_index], in config order.
  std::vector<std::size_t> sensors_on_bus(std::size_t bus_index) const;
};

/// Constructs the drivers of `cfg` (no I/O).  Throws std::runtime_error when the config refers
/// to something unknown (cannot happen for a config from load_machine_config).
Devices make_devices(const io::MachineConfig& cfg, SupervisorOptions supervisor = {});

}  // namespace errsep::drivers

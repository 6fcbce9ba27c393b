#pragma once
// A displacement sensor read over Modbus (one register spec of the machine config, decoded to µm).
#include <atomic>
#include <cstdint>
#include <string>

#include "errsep/acq/displacement_sensor.hpp"
#include "errsep/drivers/modbus_bus.hpp"
#include "errsep/io/machine_config.hpp"

namespace errsep::drivers {

/// Per-sensor counts of read() outcomes.
struct SensorCounters {
  std::uint64_t reads = 0, ok = 0, timeouts = 0, disconnected = 0, exceptions = 0, out_of_range = 0,
                not_configured = 0;
};

class ModbusSensor final : public acq::DisplacementSensor {
 public:
  /// `bus` must outlive the sensor.  `channel` is stored in every Sample (index on its bus).
  ModbusSensor(io::SensorConfig cfg, ModbusBus& bus, std::uint16_t channel);

  const std::string& name() const override { return cfg_.name; }
  /// Checks the bus is configured and reads the register once; throws std::runtime_error naming
  /// the sensor, the register and what the device said.  Not real-time safe.
  void configure() override;
  /// One read of the value register, decoded (raw·scale + offset, µm) and range-checked:
  /// a value outside [range_min_um, range_max_um] or not finite is IoStatus::out_of_range (the
  /// value is still stored, for the record).  t_ns is the midpoint of the request.
  /// Real-time safe (uses ModbusBus::read_rt).  out.seq is left to the caller.
  acq::IoStatus read(acq::Sample& out) noexcept override;

  const io::SensorConfig& config() const noexcept { return cfg_; }
  ModbusBus& bus() noexcept { return bus_; }
  SensorCounters counters() const noexcept;

 private:
  io::SensorConfig cfg_;
  ModbusBus& bus_;
  std::uint16_t channel_;
  std::atomic<bool> configured_{false};
  struct {
    std::atomic<std::uint64_t> reads{0}, ok{0}, timeouts{0}, disconnected{0}, exceptions{0},
        out_of_range{0}, not_configured{0};
  } c_;
};

}  // namespace errsep::drivers

#pragma once
// A positioning stage driven over Modbus: target position (holding register), actual position,
// a status word with in-position and fault bits, a stop coil, optionally a fault word and a speed
// register.  None of these calls is real-time safe; they are used by the scan runner.
#include <chrono>
#include <cstdint>
#include <string>

#include "errsep/acq/stage.hpp"
#include "errsep/drivers/modbus_bus.hpp"
#include "errsep/io/machine_config.hpp"

namespace errsep::drivers {

class ModbusStage final : public acq::Stage {
 public:
  /// `bus` must outlive the stage.
  ModbusStage(io::StageConfig cfg, ModbusBus& bus);

  const std::string& name() const override { return cfg_.name; }
  /// Reads the status word once and writes the configured speed; throws std::runtime_error
  /// naming the stage and register on failure.
  void configure() override;
  /// Writes the target position (mm).  The command is accepted when the write is acknowledged.
  acq::IoStatus move_to(double position_mm) override;
  acq::IoStatus position(double& position_mm) override;
  /// Polls the status word (every ~2 ms): fault bit → IoStatus::fault; in-position bit with the
  /// actual position within position_tolerance_mm of the last target → ok; a failed request is
  /// returned as it is (the caller stops the stage); otherwise IoStatus::timeout at the deadline.
  acq::IoStatus wait_in_position(std::chrono::milliseconds timeout) override;
  /// Writes 1 to the stop coil.  When the bus is marked for reconnect it reconnects first (a stop
  /// must get through).  Never throws.
  acq::IoStatus stop() noexcept override;
  /// The fault word when configured, else the fault bit of the status word (0/1).
  acq::IoStatus fault_code(unsigned& code) override;

  /// Reads the status word (raw bits).
  acq::IoStatus status_word(std::uint16_t& bits);
  const io::StageConfig& config() const noexcept { return cfg_; }
  double last_target_mm() const noexcept { return target_mm_; }

 private:
  io::StageConfig cfg_;
  ModbusBus& bus_;
  double target_mm_ = 0.0;
  bool have_target_ = false;
};

}  // namespace errsep::drivers

#include "errsep/drivers/modbus_stage.hpp"

#include <cmath>
#include <stdexcept>
#include <thread>

#include "errsep/acq/register_map.hpp"

namespace errsep::drivers {

using acq::IoStatus;

ModbusStage::ModbusStage(io::StageConfig cfg, ModbusBus& bus) : cfg_(std::move(cfg)), bus_(bus) {}

void ModbusStage::configure() {
  auto fail = [&](const std::string& what, IoStatus st) {
    std::string msg = "stage '" + cfg_.name + "' on bus '" + bus_.name() + "' (" + bus_.describe() +
                      "): " + what + " failed: " + acq::to_string(st);
    if (st == IoStatus::device_exception)
      msg += " (Modbus exception " + std::to_string(bus_.counters().last_exception_code) +
             "; check the [[stage]] registers in the config)";
    throw std::runtime_error(msg);
  };
  if (!bus_.configured())
    throw std::runtime_error("stage '" + cfg_.name + "': bus '" + bus_.name() +
                             "' is not configured (configure the bus first)");
  std::uint16_t bits = 0;
  if (IoStatus st = status_word(bits); st != IoStatus::ok)
    fail("reading the status register " + std::to_string(cfg_.status.address), st);
  double pos = 0;
  if (IoStatus st = position(pos); st != IoStatus::ok)
    fail("reading the actual position register " + std::to_string(cfg_.actual_position.address),
         st);
  if (cfg_.speed && cfg_.speed_mm_s > 0.0) {
    std::uint16_t w[2] = {0, 0};
    if (!acq::encode(*cfg_.speed, cfg_.speed_mm_s, w))
      throw std::runtime_error("stage '" + cfg_.name +
                               "': speed_mm_s = " + std::to_string(cfg_.speed_mm_s) +
                               " does not fit the speed register's type");
    if (IoStatus st = bus_.write(*cfg_.speed, w); st != IoStatus::ok)
      fail("writing the speed register " + std::to_string(cfg_.speed->address), st);
  }
}

IoStatus ModbusStage::move_to(double position_mm) {
  std::uint16_t w[2] = {0, 0};
  if (!acq::encode(cfg_.target_position, position_mm, w)) return IoStatus::out_of_range;
  const IoStatus st = bus_.write(cfg_.target_position, w);
  if (st == IoStatus::ok) {
    // The position the drive will really go to (after the register's rounding).
    target_mm_ = acq::decode(cfg_.target_position, w);
    have_target_ = true;
  }
  return st;
}

IoStatus ModbusStage::position(double& position_mm) {
  std::uint16_t w[2] = {0, 0};
  const IoStatus st = bus_.read(cfg_.actual_position, w);
  if (st == IoStatus::ok) position_mm = acq::decode(cfg_.actual_position, w);
  return st;
}

IoStatus ModbusStage::status_word(std::uint16_t& bits) {
  std::uint16_t w[2] = {0, 0};
  const IoStatus st = bus_.read(cfg_.status, w);
  if (st == IoStatus::ok) bits = w[0];
  return st;
}

IoStatus ModbusStage::wait_in_position(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    std::uint16_t bits = 0;
    if (IoStatus st = status_word(bits); st != IoStatus::ok) return st;
    if (bits & (1u << cfg_.fault_bit)) return IoStatus::fault;
    if (bits & (1u << cfg_.in_position_bit)) {
      double pos = 0;
      if (IoStatus st = position(pos); st != IoStatus::ok) return st;
      if (!have_target_ || std::abs(pos - target_mm_) <= cfg_.position_tolerance_mm)
        return IoStatus::ok;
    }
    if (std::chrono::steady_clock::now() >= deadline) return IoStatus::timeout;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

IoStatus ModbusStage::stop() noexcept {
  if (bus_.needs_reconnect()) bus_.reconnect();
  return bus_.write_coil(cfg_.stop_coil, true);
}

IoStatus ModbusStage::fault_code(unsigned& code) {
  if (cfg_.fault_code) {
    std::uint16_t w[2] = {0, 0};
    const IoStatus st = bus_.read(*cfg_.fault_code, w);
    if (st == IoStatus::ok) code = static_cast<unsigned>(acq::decode_raw(*cfg_.fault_code, w));
    return st;
  }
  std::uint16_t bits = 0;
  const IoStatus st = status_word(bits);
  if (st == IoStatus::ok) code = (bits >> cfg_.fault_bit) & 1u;
  return st;
}

}  // namespace errsep::drivers

#include "errsep/drivers/modbus_sensor.hpp"

#include <cmath>
#include <ctime>
#include <limits>
#include <stdexcept>

#include "errsep/acq/register_map.hpp"

namespace errsep::drivers {
namespace {

std::int64_t now_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

std::string where(const io::RegisterSpec& r) {
  return std::string(io::to_string(r.kind)) + " register " + std::to_string(r.address) + " (unit " +
         std::to_string(r.unit_id) + ", " + io::to_string(r.type) + ")";
}

}  // namespace

ModbusSensor::ModbusSensor(io::SensorConfig cfg, ModbusBus& bus, std::uint16_t channel)
    : cfg_(std::move(cfg)), bus_(bus), channel_(channel) {}

void ModbusSensor::configure() {
  if (!bus_.configured())
    throw std::runtime_error("sensor '" + cfg_.name + "': bus '" + bus_.name() +
                             "' is not configured (configure the bus first)");
  std::uint16_t w[2] = {0, 0};
  const acq::IoStatus st = bus_.read(cfg_.reg, w);
  if (st == acq::IoStatus::device_exception)
    throw std::runtime_error("sensor '" + cfg_.name + "': the device on bus '" + bus_.name() +
                             "' answered Modbus exception " +
                             std::to_string(bus_.counters().last_exception_code) + " for " +
                             where(cfg_.reg) + ": check the [[sensor]] register in the config");
  if (st != acq::IoStatus::ok)
    throw std::runtime_error("sensor '" + cfg_.name + "': reading " + where(cfg_.reg) +
                             " on bus '" + bus_.name() + "' (" + bus_.describe() +
                             ") failed: " + acq::to_string(st));
  configured_.store(true, std::memory_order_release);
}

acq::IoStatus ModbusSensor::read(acq::Sample& out) noexcept {
  c_.reads.fetch_add(1, std::memory_order_relaxed);
  out.channel = channel_;
  if (!configured_.load(std::memory_order_acquire)) {
    c_.not_configured.fetch_add(1, std::memory_order_relaxed);
    out.status = acq::IoStatus::not_configured;
    out.t_ns = now_ns();
    return out.status;
  }
  std::uint16_t w[2] = {0, 0};
  const std::int64_t t0 = now_ns();
  acq::IoStatus st = bus_.read_rt(cfg_.reg, w);
  const std::int64_t t1 = now_ns();
  out.t_ns = t0 + (t1 - t0) / 2;
  switch (st) {
    case acq::IoStatus::ok: {
      const double v = acq::decode(cfg_.reg, w);
      out.value = v;
      if (!std::isfinite(v) || v < cfg_.range_min_um || v > cfg_.range_max_um) {
        st = acq::IoStatus::out_of_range;
        c_.out_of_range.fetch_add(1, std::memory_order_relaxed);
      } else {
        c_.ok.fetch_add(1, std::memory_order_relaxed);
      }
      break;
    }
    case acq::IoStatus::timeout:
      c_.timeouts.fetch_add(1, std::memory_order_relaxed);
      break;
    case acq::IoStatus::disconnected:
      c_.disconnected.fetch_add(1, std::memory_order_relaxed);
      break;
    case acq::IoStatus::device_exception:
      c_.exceptions.fetch_add(1, std::memory_order_relaxed);
      break;
    default:
      c_.not_configured.fetch_add(1, std::memory_order_relaxed);
      break;
  }
  if (st != acq::IoStatus::ok && st != acq::IoStatus::out_of_range)
    out.value = std::numeric_limits<double>::quiet_NaN();  // nothing was read: no stale value
  out.status = st;
  return st;
}

SensorCounters ModbusSensor::counters() const noexcept {
  SensorCounters s;
  s.reads = c_.reads.load(std::memory_order_relaxed);
  s.ok = c_.ok.load(std::memory_order_relaxed);
  s.timeouts = c_.timeouts.load(std::memory_order_relaxed);
  s.disconnected = c_.disconnected.load(std::memory_order_relaxed);
  s.exceptions = c_.exceptions.load(std::memory_order_relaxed);
  s.out_of_range = c_.out_of_range.load(std::memory_order_relaxed);
  s.not_configured = c_.not_configured.load(std::memory_order_relaxed);
  return s;
}

}  // namespace errsep::drivers

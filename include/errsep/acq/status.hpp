#pragma once
// Status codes of the real-time path: drivers and the sampler return these instead of throwing.
#include <cstdint>

namespace errsep::acq {

enum class IoStatus : std::uint8_t {
  ok = 0,
  timeout,           ///< no answer within the response timeout (after the configured retries)
  disconnected,      ///< link down (EPIPE, ECONNRESET, not connected): the supervisor reconnects
  device_exception,  ///< the device answered with an exception (e.g. Modbus exception code)
  out_of_range,      ///< a value outside the configured measuring range
  fault,             ///< the device reports a fault (stage drive fault, limit switch, ...)
  not_configured,    ///< configure()/activate() has not succeeded
};

/// Short lower-case name ("ok", "timeout", ...), for logs and CSV metadata.  Real-time safe.
constexpr const char* to_string(IoStatus s) noexcept {
  switch (s) {
    case IoStatus::ok:
      return "ok";
    case IoStatus::timeout:
      return "timeout";
    case IoStatus::disconnected:
      return "disconnected";
    case IoStatus::device_exception:
      return "device_exception";
    case IoStatus::out_of_range:
      return "out_of_range";
    case IoStatus::fault:
      return "fault";
    case IoStatus::not_configured:
      return "not_configured";
  }
  return "unknown";
}

}  // namespace errsep::acq

#pragma once
// Driver interface of a displacement sensor.  The solver core knows nothing of it.
//
// Life cycle (ros2_control style): configure() allocates and opens (not real-time safe), then
// read() is called cyclically from the sampling thread (real-time safe: no allocation, no lock,
// no exception, bounded time), deactivate() closes.
#include <string>

#include "errsep/acq/sample.hpp"

namespace errsep::acq {

class DisplacementSensor {
 public:
  DisplacementSensor() = default;
  DisplacementSensor(const DisplacementSensor&) = delete;
  DisplacementSensor& operator=(const DisplacementSensor&) = delete;
  virtual ~DisplacementSensor() = default;

  /// Human-readable name from the machine config ("sensor1", ...).
  virtual const std::string& name() const = 0;
  /// Opens the device; throws std::runtime_error with an actionable message.  Not real-time safe.
  virtual void configure() = 0;
  /// Reads one value in µm into `out.value` and stamps `out.t_ns` (CLOCK_MONOTONIC).
  /// Real-time safe.  Returns the status also stored in out.status.
  virtual IoStatus read(Sample& out) noexcept = 0;
};

}  // namespace errsep::acq

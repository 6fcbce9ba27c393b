#pragma once
// Driver interface of a positioning stage (the slide of the slideway, or the sensor stage).
// Positions are in mm.  None of these calls is real-time safe unless stated; they are used by the
// scan runner, not by the sampling thread.
#include <chrono>
#include <string>

#include "errsep/acq/status.hpp"

namespace errsep::acq {

class Stage {
 public:
  Stage() = default;
  Stage(const Stage&) = delete;
  Stage& operator=(const Stage&) = delete;
  virtual ~Stage() = default;

  virtual const std::string& name() const = 0;
  /// Opens the device; throws std::runtime_error with an actionable message.
  virtual void configure() = 0;
  /// Commands a move to an absolute position (returns once the command is accepted).
  virtual IoStatus move_to(double position_mm) = 0;
  /// Reads the actual position.
  virtual IoStatus position(double& position_mm) = 0;
  /// Waits until the stage reports in-position (and settled), or the timeout passes
  /// (IoStatus::timeout), or a fault is reported (IoStatus::fault).
  virtual IoStatus wait_in_position(std::chrono::milliseconds timeout) = 0;
  /// Stops motion now (Ctrl-C, SIGTERM, faults).  Best effort; never throws.
  virtual IoStatus stop() noexcept = 0;
  /// Fault word of the drive (0 = none).
  virtual IoStatus fault_code(unsigned& code) = 0;
};

}  // namespace errsep::acq

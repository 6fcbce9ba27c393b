#pragma once
// Digital I/O over libgpiod 1.6 (the C API Debian 12 ships): edge events on the input lines of
// the machine config's [gpio] (start button, trigger / encoder index) and one output line.
//
// The C API is used directly rather than the C++ binding because the binding's
// line_bulk::get_values() returns a new std::vector on every call (NOTES.md): here the bulk
// calls fill caller-owned buffers, and the line bulks live in the object, so the cyclic calls
// allocate nothing.  <gpiod.h> stays inside the .cpp (pimpl).
#include <chrono>
#include <cstddef>
#include <memory>
#include <string>

#include "errsep/acq/digital_io.hpp"
#include "errsep/io/machine_config.hpp"

namespace errsep::drivers {

class GpiodIo final : public acq::DigitalIo {
 public:
  /// Lines < 0 in `cfg` are unused.  Nothing is opened here.
  explicit GpiodIo(io::GpioConfig cfg, std::string consumer = "errsep");
  ~GpiodIo() override;

  /// Opens the chip (gpiod_chip_open_lookup: a name such as "gpiochip0", a path, a label or a
  /// number), requests the input lines for both edges and the output line (initially 0).  Throws
  /// std::runtime_error naming the chip when it does not exist or cannot be opened, or naming the
  /// line when a line cannot be requested (e.g. busy).  Not real-time safe.
  void configure() override;
  /// Waits up to `timeout` for an edge on any input line (gpiod_line_event_wait_bulk), reads one
  /// event (gpiod_line_event_read): its kernel timestamp, line offset and edge.  IoStatus::timeout
  /// when none; not_configured without input lines.  Real-time safe in the sense of the
  /// sampling path: no allocation, no lock, no exception (it blocks up to `timeout` by design).
  acq::IoStatus wait_edge(acq::EdgeEvent& ev, std::chrono::milliseconds timeout) override;
  /// Sets the configured output line (gpiod_line_set_value).  out_of_range for any other line.
  /// Real-time safe.
  acq::IoStatus set_output(unsigned line, bool value) override;
  /// Reads the input lines' current levels into `values` (at most `n`, in the order start_line,
  /// trigger_line of those configured) with one gpiod_line_get_value_bulk call into the caller's
  /// buffer.  Real-time safe: no allocation.
  acq::IoStatus read_inputs(int* values, std::size_t n) noexcept;
  /// Number of input lines requested (0..2).
  std::size_t input_count() const noexcept;

  const io::GpioConfig& config() const noexcept { return cfg_; }

 private:
  struct Impl;
  io::GpioConfig cfg_;
  std::string consumer_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace errsep::drivers

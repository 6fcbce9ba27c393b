#pragma once
// Driver interface of digital I/O: edge events on input lines (start button, encoder index,
// trigger) and output lines.
#include <chrono>
#include <cstdint>
#include <string>

#include "errsep/acq/status.hpp"

namespace errsep::acq {

enum class Edge : std::uint8_t { rising, falling };

struct EdgeEvent {
  std::int64_t t_ns = 0;  ///< kernel timestamp of the edge, ns
  unsigned line = 0;      ///< offset of the line on its chip
  Edge edge = Edge::rising;
};

class DigitalIo {
 public:
  DigitalIo() = default;
  DigitalIo(const DigitalIo&) = delete;
  DigitalIo& operator=(const DigitalIo&) = delete;
  virtual ~DigitalIo() = default;

  /// Opens the chip and requests the lines; throws std::runtime_error naming the chip when it
  /// does not exist or cannot be opened.
  virtual void configure() = 0;
  /// Waits up to `timeout` for an edge on any requested input line.  IoStatus::timeout if none.
  virtual IoStatus wait_edge(EdgeEvent& ev, std::chrono::milliseconds timeout) = 0;
  /// Sets an output line.
  virtual IoStatus set_output(unsigned line, bool value) = 0;
};

}  // namespace errsep::acq

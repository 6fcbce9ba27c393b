#include "errsep/acq/digital_trigger.hpp"

#include <algorithm>

namespace errsep::acq {

IoStatus wait_for_rising_edge(DigitalIo& io, unsigned line, std::chrono::milliseconds timeout,
                              EdgeEvent& out, const std::atomic<bool>* abort) {
  using clock = std::chrono::steady_clock;
  const auto until = clock::now() + timeout;
  for (;;) {
    if (abort && abort->load(std::memory_order_acquire)) return IoStatus::timeout;
    const auto left = std::chrono::ceil<std::chrono::milliseconds>(until - clock::now());
    if (left.count() <= 0) return IoStatus::timeout;
    EdgeEvent ev;
    const IoStatus st = io.wait_edge(ev, std::min(left, std::chrono::milliseconds(100)));
    if (st == IoStatus::timeout) continue;
    if (st != IoStatus::ok) return st;
    if (ev.line == line && ev.edge == Edge::rising) {
      out = ev;
      return IoStatus::ok;
    }
  }
}

}  // namespace errsep::acq

#include "errsep/core/displacement_scan_order.hpp"

#include <stdexcept>

namespace errsep::core {

const char* to_string(DisplacementScanOrder o) noexcept {
  return o == DisplacementScanOrder::backward ? "backward" : "forward";
}

DisplacementScanOrder displacement_scan_order_from_string(const std::string& name) {
  if (name == "forward") return DisplacementScanOrder::forward;
  if (name == "backward") return DisplacementScanOrder::backward;
  throw std::invalid_argument("unknown scan 2 order '" + name + "': one of " +
                              displacement_scan_order_names());
}

const char* displacement_scan_order_names() noexcept {
  return "forward, backward";
}

}  // namespace errsep::core

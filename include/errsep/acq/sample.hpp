#pragma once
// A timestamped reading, trivially copyable so it can travel through the lock-free ring.
#include <cstdint>
#include <type_traits>

#include "errsep/acq/status.hpp"

namespace errsep::acq {

struct Sample {
  std::int64_t t_ns = 0;      ///< CLOCK_MONOTONIC time of the reading, ns
  std::uint64_t seq = 0;      ///< sequence number of the sampling period (gaps = missed periods)
  std::uint16_t channel = 0;  ///< index of the sensor within its bus
  IoStatus status = IoStatus::ok;
  double value = 0.0;  ///< µm for displacement sensors, mm for stage positions
};
static_assert(std::is_trivially_copyable_v<Sample>);

}  // namespace errsep::acq

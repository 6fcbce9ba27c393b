#pragma once
// Waiting for a start button / trigger on a DigitalIo: a rising edge on one line, ignoring the
// other lines' edges and falling edges, giving up on timeout or abort.
#include <atomic>
#include <chrono>

#include "errsep/acq/digital_io.hpp"

namespace errsep::acq {

/// Waits up to `timeout` for a rising edge on `line`; fills `out` and returns IoStatus::ok, or
/// timeout (also when `abort` became true; checked every 100 ms), or the status of a failing
/// wait_edge().  Not real-time safe (blocks); used by the scan app and the daemon, not by the
/// sampler.
IoStatus wait_for_rising_edge(DigitalIo& io, unsigned line, std::chrono::milliseconds timeout,
                              EdgeEvent& out, const std::atomic<bool>* abort = nullptr);

}  // namespace errsep::acq

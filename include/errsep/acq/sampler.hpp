#pragma once
// The sampling thread of one bus, and the consumer that drains its ring.
//
// One Sampler per physical bus (a libmodbus context is not thread-safe, NOTES.md): its thread
// reads every sensor of the bus once per period, on an absolute-time schedule
// (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)), so a late wake-up does not shift every
// later period (no drift), and pushes one timestamped Sample per sensor into a lock-free SPSC
// ring.  Nothing on that path allocates, locks, does I/O of its own (the sensor read is the only
// I/O, and it is the driver's real-time-safe read()), or throws: problems become counters.
//
// Counters, all reported in the scan's metadata:
//  - missed periods: a period whose deadline was already a whole period or more in the past when
//    the loop could start it is skipped, not caught up in a burst; Sample::seq is the period
//    index, so the gap in seq of the next sample shows it too (skips are counted when the next
//    period starts, so the seq gaps of the recorded samples add up to the count exactly);
//  - overruns: samples the ring refused because it was full (the consumer fell behind);
//  - reads by status: one count per IoStatus (ok, timeout, ...);
//  - period jitter: lateness of each period's start after its deadline (the wake-up latency
//    cyclictest measures), in a fixed 1 µs-bin histogram allocated at construction, with the
//    exact maximum kept separately.
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "errsep/acq/displacement_sensor.hpp"
#include "errsep/acq/realtime.hpp"
#include "errsep/acq/sample.hpp"
#include "errsep/acq/spsc_ring.hpp"
#include "errsep/acq/status.hpp"

namespace errsep::acq {

/// Number of IoStatus values (for per-status counters).
inline constexpr std::size_t kIoStatusCount =
    static_cast<std::size_t>(IoStatus::not_configured) + 1;

/// CLOCK_MONOTONIC now, ns.  Real-time safe (vDSO, no allocation).
std::int64_t monotonic_ns() noexcept;

struct SamplerOptions {
  double rate_hz = 1000.0;          ///< sampling periods per second (every sensor read once each)
  RealtimeOptions realtime;         ///< applied on the sampling thread only
  int jitter_histogram_us = 20000;  ///< histogram range (1 µs bins); later wake-ups: overflow bin
  std::uint16_t channel_base = 0;   ///< Sample::channel = channel_base + index of the sensor

  /// Period in ns (rounded to the nearest ns).
  std::int64_t period_ns() const;
  bool is_valid(std::string* why = nullptr) const;
};

/// Percentiles of the period jitter, µs (1 µs resolution up to the histogram range).
struct JitterStats {
  std::uint64_t count = 0;  ///< periods measured
  double p50_us = 0, p99_us = 0, p999_us = 0;
  double max_us = 0;  ///< exact
  double mean_us = 0;
  std::uint64_t beyond_range = 0;  ///< periods later than the histogram range
};

struct SamplerStats {
  std::uint64_t periods = 0;         ///< periods executed (each reads every sensor once)
  std::uint64_t missed_periods = 0;  ///< periods skipped because the loop was a period late
  std::uint64_t samples_pushed = 0;  ///< samples accepted by the ring
  std::uint64_t overruns = 0;        ///< samples refused by a full ring (lost, counted)
  std::array<std::uint64_t, kIoStatusCount> reads_by_status{};  ///< index = IoStatus value
  JitterStats jitter;
  RealtimeReport realtime;  ///< what the sampling thread's real-time set-up achieved

  std::uint64_t read_errors() const;  ///< all reads whose status was not ok
  /// One line with every counter, for logs and CSV metadata.
  std::string brief() const;
};

/// A dedicated sampling thread for the sensors of one bus.
class Sampler {
 public:
  /// `sensors` must be configured and outlive the sampler; `ring` receives the samples and must
  /// outlive it.  Allocates the jitter histogram.  Throws std::invalid_argument for invalid
  /// options or no sensors.  Not real-time safe.
  /// `channels`, when given, is Sample::channel per sensor (same length as `sensors`); when
  /// empty, sensor i gets channel_base + i.
  Sampler(std::vector<DisplacementSensor*> sensors, SpscRing<Sample>& ring, SamplerOptions opts,
          std::vector<std::uint16_t> channels = {});
  ~Sampler();  ///< stops the thread if running
  Sampler(const Sampler&) = delete;
  Sampler& operator=(const Sampler&) = delete;

  /// Starts the thread and returns once it has applied its real-time set-up (whose warnings are
  /// in stats().realtime).  Throws std::logic_error if already started.  Not real-time safe.
  void start();
  /// Asks the thread to stop and joins it (returns within about one period plus one read).
  /// Idempotent.  Not real-time safe.
  void stop();
  bool running() const noexcept { return running_.load(std::memory_order_acquire); }

  /// Periods executed so far.  Real-time safe; any thread.
  std::uint64_t periods() const noexcept { return periods_.load(std::memory_order_acquire); }
  /// A snapshot of every counter (exact after stop()).  Not real-time safe (computes
  /// percentiles, copies strings); any thread.
  SamplerStats stats() const;
  const SamplerOptions& options() const noexcept { return opts_; }

 private:
  void loop() noexcept;
  void record_jitter(std::int64_t late_ns) noexcept;
  static void bump(std::atomic<std::uint64_t>& c, std::uint64_t n = 1) noexcept {
    // Single writer (the sampling thread): load + store, no read-modify-write needed.
    c.store(c.load(std::memory_order_relaxed) + n, std::memory_order_relaxed);
  }

  std::vector<DisplacementSensor*> sensors_;
  std::vector<std::uint16_t> channels_;
  SpscRing<Sample>& ring_;
  SamplerOptions opts_;
  std::int64_t period_ns_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> running_{false};
  RealtimeReport rt_report_;  // written by the thread before it signals readiness

  std::atomic<std::uint64_t> periods_{0}, missed_{0}, pushed_{0}, overruns_{0};
  std::array<std::atomic<std::uint64_t>, kIoStatusCount> by_status_{};
  std::unique_ptr<std::atomic<std::uint64_t>[]> hist_;  // jitter_histogram_us + 1 bins
  std::atomic<std::int64_t> jitter_max_ns_{0};
  std::atomic<std::int64_t> jitter_sum_ns_{0};
  std::atomic<std::uint64_t> jitter_count_{0};
};

/// Drains one or more rings on a (non-real-time) consumer thread and hands every sample to a
/// sink, in order per ring.  The sink runs on the consumer thread; it may allocate and lock.
class RingConsumer {
 public:
  using Sink = std::function<void(const Sample&)>;
  /// `rings` must outlive the consumer.  `idle_sleep` is how long it sleeps when every ring is
  /// empty (bounds the latency of the scan and the CPU use of polling).
  RingConsumer(std::vector<SpscRing<Sample>*> rings, Sink sink,
               std::chrono::microseconds idle_sleep = std::chrono::microseconds(200));
  ~RingConsumer();
  RingConsumer(const RingConsumer&) = delete;
  RingConsumer& operator=(const RingConsumer&) = delete;

  void start();
  /// Stops after draining what is in the rings now (stop the samplers first so that nothing is
  /// left behind).  Idempotent.
  void stop();
  /// Samples handed to the sink so far.  Any thread.
  std::uint64_t consumed() const noexcept { return consumed_.load(std::memory_order_acquire); }

 private:
  std::size_t drain_once();
  std::vector<SpscRing<Sample>*> rings_;
  Sink sink_;
  std::chrono::microseconds idle_sleep_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> consumed_{0};
};

/// Averages K readings per channel from samples that arrive after a window was opened: what a
/// scan does at each slide position after settling.  Thread-safe (the consumer thread feeds it,
/// the scan thread waits on it).  Not real-time safe (uses a mutex): never call from a sampler.
class WindowAverager {
 public:
  explicit WindowAverager(std::size_t channels);

  /// Result of one window.
  struct Window {
    std::vector<double> mean;             ///< per channel, of the ok samples (NaN if none)
    std::vector<double> t_mean_ns;        ///< mean CLOCK_MONOTONIC time of those samples
    std::vector<std::uint64_t> n_ok;      ///< ok samples averaged per channel
    std::vector<std::uint64_t> n_errors;  ///< non-ok samples seen per channel in the window
    IoStatus last_error = IoStatus::ok;   ///< status of the most recent non-ok sample
    bool complete = false;                ///< every channel reached K ok samples
  };

  /// Consumer thread: account one sample (any channel; unknown channels are ignored).
  void add(const Sample& s);
  /// Scan thread: starts collecting `k` ok samples per channel from those stamped at or after
  /// `t_start_ns`.  Samples of a previous window are discarded.
  void open(std::int64_t t_start_ns, std::uint64_t k);
  /// Waits until every channel has K ok samples, or `timeout` passes, or some channel has seen
  /// more than `max_errors` non-ok samples in this window, or `abort` becomes true.  Returns
  /// what was collected (complete tells which).
  Window wait(std::chrono::milliseconds timeout, std::uint64_t max_errors,
              const std::atomic<bool>* abort = nullptr);
  /// Samples seen in total (any window or none).
  std::uint64_t total() const;

 private:
  bool done_locked() const;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::size_t channels_;
  bool open_ = false;
  std::int64_t t_start_ns_ = 0;
  std::uint64_t k_ = 0, max_errors_ = 0, total_ = 0;
  std::vector<double> sum_, tsum_;
  std::vector<std::uint64_t> n_ok_, n_err_;
  IoStatus last_error_ = IoStatus::ok;
};

}  // namespace errsep::acq

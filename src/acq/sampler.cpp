#include "errsep/acq/sampler.hpp"

#include <sys/prctl.h>
#include <time.h>

#include <cerrno>
#include <cmath>
#include <future>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace errsep::acq {
namespace {

constexpr std::int64_t kNsPerS = 1'000'000'000;

timespec to_timespec(std::int64_t ns) noexcept {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(ns / kNsPerS);
  ts.tv_nsec = static_cast<long>(ns % kNsPerS);
  return ts;
}

/// Sleeps until the absolute CLOCK_MONOTONIC time `deadline_ns`.  Real-time safe.
void sleep_until_ns(std::int64_t deadline_ns) noexcept {
  const timespec ts = to_timespec(deadline_ns);
  // EINTR (a signal such as SIGINT): sleep again to the same absolute deadline, no drift.
  while (::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

}  // namespace

std::int64_t monotonic_ns() noexcept {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * kNsPerS + ts.tv_nsec;
}

std::int64_t SamplerOptions::period_ns() const {
  return static_cast<std::int64_t>(std::llround(1e9 / rate_hz));
}

bool SamplerOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(rate_hz > 0.0) || rate_hz > 100000.0 || !std::isfinite(rate_hz))
    return fail("sampler.rate_hz = " + std::to_string(rate_hz) + ": must be in (0, 100000]");
  if (jitter_histogram_us < 100 || jitter_histogram_us > 10'000'000)
    return fail("sampler.jitter_histogram_us = " + std::to_string(jitter_histogram_us) +
                ": must be in [100, 10000000]");
  return realtime.is_valid(why);
}

std::uint64_t SamplerStats::read_errors() const {
  std::uint64_t n = 0;
  for (std::size_t i = 1; i < reads_by_status.size(); ++i)
    n += reads_by_status[i];
  return n;
}

std::string SamplerStats::brief() const {
  std::ostringstream os;
  os << "periods " << periods << ", missed " << missed_periods << ", samples " << samples_pushed
     << ", overruns " << overruns << ", read errors " << read_errors();
  for (std::size_t i = 1; i < reads_by_status.size(); ++i)
    if (reads_by_status[i] > 0)
      os << " (" << to_string(static_cast<IoStatus>(i)) << " " << reads_by_status[i] << ")";
  os << ", jitter p50 " << jitter.p50_us << " us p99 " << jitter.p99_us << " us max "
     << jitter.max_us << " us";
  return os.str();
}

Sampler::Sampler(std::vector<DisplacementSensor*> sensors, SpscRing<Sample>& ring,
                 SamplerOptions opts, std::vector<std::uint16_t> channels)
    : sensors_(std::move(sensors)), channels_(std::move(channels)), ring_(ring), opts_(opts) {
  std::string why;
  if (!opts_.is_valid(&why)) throw std::invalid_argument("Sampler: " + why);
  if (sensors_.empty()) throw std::invalid_argument("Sampler: no sensors on this bus");
  for (auto* s : sensors_)
    if (s == nullptr) throw std::invalid_argument("Sampler: null sensor");
  if (channels_.empty())
    for (std::size_t i = 0; i < sensors_.size(); ++i)
      channels_.push_back(static_cast<std::uint16_t>(opts_.channel_base + i));
  if (channels_.size() != sensors_.size())
    throw std::invalid_argument("Sampler: " + std::to_string(channels_.size()) + " channels for " +
                                std::to_string(sensors_.size()) + " sensors");
  period_ns_ = opts_.period_ns();
  const auto bins = static_cast<std::size_t>(opts_.jitter_histogram_us) + 1;
  hist_ = std::make_unique<std::atomic<std::uint64_t>[]>(bins);
  for (std::size_t i = 0; i < bins; ++i)
    hist_[i].store(0, std::memory_order_relaxed);
}

Sampler::~Sampler() {
  stop();
}

void Sampler::start() {
  if (thread_.joinable()) throw std::logic_error("Sampler::start: already started");
  stop_.store(false, std::memory_order_release);
  std::promise<void> ready;
  auto ready_future = ready.get_future();
  thread_ = std::thread([this, &ready] {
    // Set-up (may allocate: the report's strings) happens before the real-time loop.
    rt_report_ = apply_realtime(opts_.realtime);
    // A SCHED_OTHER thread's sleeps end up to 50 µs late by default (timer slack); the sampler
    // wants its deadlines, so ask for 1 ns (no privilege needed; ignored under SCHED_FIFO).
    (void)::prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
    running_.store(true, std::memory_order_release);
    ready.set_value();
    loop();
    running_.store(false, std::memory_order_release);
  });
  ready_future.wait();
}

void Sampler::stop() {
  stop_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
}

void Sampler::record_jitter(std::int64_t late_ns) noexcept {
  if (late_ns < 0) late_ns = 0;
  const std::int64_t us = late_ns / 1000;
  const auto last = static_cast<std::int64_t>(opts_.jitter_histogram_us);
  bump(hist_[static_cast<std::size_t>(us < last ? us : last)]);
  if (late_ns > jitter_max_ns_.load(std::memory_order_relaxed))
    jitter_max_ns_.store(late_ns, std::memory_order_relaxed);
  jitter_sum_ns_.store(jitter_sum_ns_.load(std::memory_order_relaxed) + late_ns,
                       std::memory_order_relaxed);
  bump(jitter_count_);
}

// The real-time loop.  Real-time safe: no allocation, lock, exception or I/O of its own; the
// only blocking calls are clock_nanosleep and the drivers' noexcept read().
void Sampler::loop() noexcept {
  const std::int64_t t0 = monotonic_ns() + period_ns_;  // first deadline one period from now
  std::uint64_t k = 0;                                  // index of the current period
  Sample s;
  std::uint64_t skipped = 0;  // periods skipped before period k, counted once k really starts
  while (!stop_.load(std::memory_order_acquire)) {
    if (skipped) bump(missed_, skipped);  // so seq gaps of the samples == missed periods, exactly
    skipped = 0;
    const std::int64_t deadline = t0 + static_cast<std::int64_t>(k) * period_ns_;
    sleep_until_ns(deadline);
    const std::int64_t woke = monotonic_ns();
    record_jitter(woke - deadline);
    for (std::size_t i = 0; i < sensors_.size(); ++i) {
      s = Sample{};
      const IoStatus st = sensors_[i]->read(s);
      s.status = st;
      s.seq = k;
      s.channel = channels_[i];
      if (s.t_ns == 0) s.t_ns = monotonic_ns();  // a driver that does not stamp
      bump(by_status_[static_cast<std::size_t>(st) < kIoStatusCount
                          ? static_cast<std::size_t>(st)
                          : static_cast<std::size_t>(IoStatus::fault)]);
      if (ring_.try_push(s))
        bump(pushed_);
      else
        bump(overruns_);
    }
    periods_.store(periods_.load(std::memory_order_relaxed) + 1, std::memory_order_release);
    // Next period; skip (and count) those whose deadline passed a whole period or more ago.
    ++k;
    const std::int64_t now = monotonic_ns();
    const std::int64_t next = t0 + static_cast<std::int64_t>(k) * period_ns_;
    if (now - next >= period_ns_) {
      skipped = static_cast<std::uint64_t>((now - next) / period_ns_);
      k += skipped;
    }
  }
}

SamplerStats Sampler::stats() const {
  SamplerStats st;
  st.periods = periods_.load(std::memory_order_acquire);
  st.missed_periods = missed_.load(std::memory_order_relaxed);
  st.samples_pushed = pushed_.load(std::memory_order_relaxed);
  st.overruns = overruns_.load(std::memory_order_relaxed);
  for (std::size_t i = 0; i < kIoStatusCount; ++i)
    st.reads_by_status[i] = by_status_[i].load(std::memory_order_relaxed);
  st.realtime = rt_report_;  // written once by the thread before start() returned

  JitterStats& j = st.jitter;
  const auto bins = static_cast<std::size_t>(opts_.jitter_histogram_us) + 1;
  std::vector<std::uint64_t> h(bins);
  std::uint64_t total = 0;
  for (std::size_t i = 0; i < bins; ++i)
    total += (h[i] = hist_[i].load(std::memory_order_relaxed));
  j.count = total;
  j.beyond_range = h[bins - 1];
  j.max_us = static_cast<double>(jitter_max_ns_.load(std::memory_order_relaxed)) / 1000.0;
  const auto n = jitter_count_.load(std::memory_order_relaxed);
  j.mean_us = n ? static_cast<double>(jitter_sum_ns_.load(std::memory_order_relaxed)) / 1000.0 /
                      static_cast<double>(n)
                : 0.0;
  // Percentile q: the upper edge of the first bin where the cumulative count reaches q·total
  // (a conservative estimate, never below the true value by more than the 1 µs bin).
  auto pct = [&](double q) {
    if (total == 0) return 0.0;
    const auto target = static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(total)));
    std::uint64_t cum = 0;
    for (std::size_t i = 0; i < bins; ++i) {
      cum += h[i];
      if (cum >= target) return i + 1 < bins ? static_cast<double>(i + 1) : j.max_us;
    }
    return j.max_us;
  };
  j.p50_us = std::min(pct(0.50), j.max_us);
  j.p99_us = std::min(pct(0.99), j.max_us);
  j.p999_us = std::min(pct(0.999), j.max_us);
  return st;
}

// ---------------------------------------------------------------------------------------------

RingConsumer::RingConsumer(std::vector<SpscRing<Sample>*> rings, Sink sink,
                           std::chrono::microseconds idle_sleep)
    : rings_(std::move(rings)), sink_(std::move(sink)), idle_sleep_(idle_sleep) {
  if (rings_.empty()) throw std::invalid_argument("RingConsumer: no rings");
  if (!sink_) throw std::invalid_argument("RingConsumer: no sink");
}

RingConsumer::~RingConsumer() {
  stop();
}

std::size_t RingConsumer::drain_once() {
  std::size_t n = 0;
  Sample s;
  for (auto* r : rings_)
    while (r->try_pop(s)) {
      sink_(s);
      ++n;
    }
  if (n) consumed_.store(consumed_.load(std::memory_order_relaxed) + n, std::memory_order_release);
  return n;
}

void RingConsumer::start() {
  if (thread_.joinable()) throw std::logic_error("RingConsumer::start: already started");
  stop_.store(false, std::memory_order_release);
  thread_ = std::thread([this] {
    while (!stop_.load(std::memory_order_acquire))
      if (drain_once() == 0) std::this_thread::sleep_for(idle_sleep_);
    drain_once();  // what was pushed before stop() (the samplers are stopped by then)
  });
}

void RingConsumer::stop() {
  stop_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
}

// ---------------------------------------------------------------------------------------------

WindowAverager::WindowAverager(std::size_t channels)
    : channels_(channels),
      sum_(channels, 0.0),
      tsum_(channels, 0.0),
      n_ok_(channels, 0),
      n_err_(channels, 0) {}

void WindowAverager::add(const Sample& s) {
  bool notify = false;
  {
    std::lock_guard lock(mu_);
    ++total_;
    if (!open_ || s.channel >= channels_ || s.t_ns < t_start_ns_) return;
    const std::size_t c = s.channel;
    if (s.status == IoStatus::ok) {
      if (n_ok_[c] < k_) {
        sum_[c] += s.value;
        tsum_[c] += static_cast<double>(s.t_ns - t_start_ns_);
        ++n_ok_[c];
      }
    } else {
      ++n_err_[c];
      last_error_ = s.status;
    }
    notify = done_locked();
  }
  if (notify) cv_.notify_all();
}

void WindowAverager::open(std::int64_t t_start_ns, std::uint64_t k) {
  std::lock_guard lock(mu_);
  open_ = true;
  t_start_ns_ = t_start_ns;
  k_ = k;
  max_errors_ = std::numeric_limits<std::uint64_t>::max();
  std::fill(sum_.begin(), sum_.end(), 0.0);
  std::fill(tsum_.begin(), tsum_.end(), 0.0);
  std::fill(n_ok_.begin(), n_ok_.end(), 0);
  std::fill(n_err_.begin(), n_err_.end(), 0);
  last_error_ = IoStatus::ok;
}

bool WindowAverager::done_locked() const {
  bool all = true;
  for (std::size_t c = 0; c < channels_; ++c) {
    if (n_err_[c] > max_errors_) return true;
    if (n_ok_[c] < k_) all = false;
  }
  return all;
}

WindowAverager::Window WindowAverager::wait(std::chrono::milliseconds timeout,
                                            std::uint64_t max_errors,
                                            const std::atomic<bool>* abort) {
  std::unique_lock lock(mu_);
  max_errors_ = max_errors;
  const auto until = std::chrono::steady_clock::now() + timeout;
  // Wake up regularly to look at the abort flag (set from a signal handler, no notify).
  while (!done_locked() && std::chrono::steady_clock::now() < until &&
         !(abort && abort->load(std::memory_order_acquire)))
    cv_.wait_for(lock, std::chrono::milliseconds(20));
  Window w;
  w.mean.resize(channels_);
  w.t_mean_ns.resize(channels_);
  w.n_ok = n_ok_;
  w.n_errors = n_err_;
  w.last_error = last_error_;
  w.complete = true;
  for (std::size_t c = 0; c < channels_; ++c) {
    if (n_ok_[c] < k_) w.complete = false;
    w.mean[c] = n_ok_[c] ? sum_[c] / static_cast<double>(n_ok_[c])
                         : std::numeric_limits<double>::quiet_NaN();
    w.t_mean_ns[c] =
        n_ok_[c] ? static_cast<double>(t_start_ns_) + tsum_[c] / static_cast<double>(n_ok_[c])
                 : std::numeric_limits<double>::quiet_NaN();
  }
  open_ = false;
  return w;
}

std::uint64_t WindowAverager::total() const {
  std::lock_guard lock(mu_);
  return total_;
}

}  // namespace errsep::acq

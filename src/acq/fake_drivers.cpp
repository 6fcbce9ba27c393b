#include "errsep/acq/fake_drivers.hpp"

#include <time.h>

#include <cmath>
#include <stdexcept>
#include <thread>

#include "errsep/acq/sampler.hpp"

namespace errsep::acq {
namespace {

void spin_sleep(std::chrono::microseconds d) noexcept {
  if (d.count() <= 0) return;
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(d.count() / 1'000'000);
  ts.tv_nsec = static_cast<long>((d.count() % 1'000'000) * 1000);
  while (::clock_nanosleep(CLOCK_MONOTONIC, 0, &ts, &ts) != 0) {
  }
}

}  // namespace

FakeSensor::FakeSensor(std::string name, ValueFn value, FakeSensorFaults faults)
    : name_(std::move(name)), value_(std::move(value)), faults_(faults) {}

void FakeSensor::configure() {
  if (faults_.throw_on_configure)
    throw std::runtime_error("fake sensor '" + name_ + "': configure failed (injected fault)");
  configured_ = true;
}

IoStatus FakeSensor::read(Sample& out) noexcept {
  if (!configured_) {
    out.status = IoStatus::not_configured;
    out.t_ns = monotonic_ns();
    return out.status;
  }
  const std::uint64_t n = reads_.load(std::memory_order_relaxed) + 1;
  reads_.store(n, std::memory_order_release);
  spin_sleep(faults_.read_time);
  if (faults_.slow_every_n && n % faults_.slow_every_n == 0) spin_sleep(faults_.slow_read);
  out.t_ns = monotonic_ns();
  if ((faults_.fail_every_n && n % faults_.fail_every_n == 0) ||
      (faults_.fail_from_read && n >= faults_.fail_from_read)) {
    out.status = faults_.fail_status;
    out.value = 0.0;
    return out.status;
  }
  out.value = value_ ? value_(out.t_ns) : 0.0;
  out.status = IoStatus::ok;
  return out.status;
}

// ---------------------------------------------------------------------------------------------

FakeStage::FakeStage(std::string name, double speed_mm_s, std::chrono::milliseconds settle,
                     double start_mm, FakeStageFaults faults)
    : name_(std::move(name)),
      speed_mm_s_(speed_mm_s),
      settle_(settle),
      faults_(faults),
      from_mm_(start_mm),
      target_mm_(start_mm) {
  if (!(speed_mm_s > 0)) throw std::invalid_argument("FakeStage: speed must be > 0");
}

void FakeStage::configure() {
  if (faults_.throw_on_configure)
    throw std::runtime_error("fake stage '" + name_ + "': configure failed (injected fault)");
  configured_ = true;
}

double FakeStage::position_now_mm() const noexcept {
  const double from = from_mm_.load(), to = target_mm_.load();
  const double dt_s = static_cast<double>(monotonic_ns() - t_start_ns_.load()) * 1e-9;
  double travelled = speed_mm_s_ * (dt_s > 0 ? dt_s : 0.0);
  if (stuck_.load()) travelled = std::min(travelled, 0.5 * std::fabs(to - from));
  if (travelled >= std::fabs(to - from)) return to;
  return from + (to > from ? travelled : -travelled);
}

IoStatus FakeStage::move_to(double position_mm) {
  if (!configured_) return IoStatus::not_configured;
  if (faulted_.load()) return IoStatus::fault;
  const std::uint64_t n = moves_.fetch_add(1) + 1;
  const double here = position_now_mm();
  stopped_ = false;
  stuck_ = (faults_.stuck_on_move == n);
  from_mm_ = here;
  target_mm_ = position_mm;
  t_start_ns_ = monotonic_ns();
  if (faults_.fault_on_move == n) faulted_ = true;
  return IoStatus::ok;
}

IoStatus FakeStage::position(double& position_mm) {
  if (!configured_) return IoStatus::not_configured;
  position_mm = position_now_mm();
  return IoStatus::ok;
}

IoStatus FakeStage::wait_in_position(std::chrono::milliseconds timeout) {
  if (!configured_) return IoStatus::not_configured;
  if (faulted_.load()) return IoStatus::fault;
  if (stuck_.load() || stopped_.load()) {
    std::this_thread::sleep_for(timeout);
    return IoStatus::timeout;
  }
  const double dist = std::fabs(target_mm_.load() - from_mm_.load());
  const auto arrive_ns = t_start_ns_.load() + static_cast<std::int64_t>(dist / speed_mm_s_ * 1e9) +
                         std::chrono::duration_cast<std::chrono::nanoseconds>(settle_).count();
  const auto wait_ns = arrive_ns - monotonic_ns();
  if (wait_ns > std::chrono::duration_cast<std::chrono::nanoseconds>(timeout).count()) {
    std::this_thread::sleep_for(timeout);
    return IoStatus::timeout;
  }
  if (wait_ns > 0) std::this_thread::sleep_for(std::chrono::nanoseconds(wait_ns));
  return IoStatus::ok;
}

IoStatus FakeStage::stop() noexcept {
  stops_.fetch_add(1);
  const double here = position_now_mm();
  from_mm_ = here;
  target_mm_ = here;
  t_start_ns_ = monotonic_ns();
  stopped_ = true;
  return IoStatus::ok;
}

IoStatus FakeStage::fault_code(unsigned& code) {
  if (!configured_) return IoStatus::not_configured;
  code = faulted_.load() ? faults_.fault_code : 0u;
  return IoStatus::ok;
}

// ---------------------------------------------------------------------------------------------

void FakeDigitalIo::configure() {
  if (throw_) throw std::runtime_error("fake digital I/O: configure failed (injected fault)");
  configured_ = true;
}

IoStatus FakeDigitalIo::wait_edge(EdgeEvent& ev, std::chrono::milliseconds timeout) {
  if (!configured_) return IoStatus::not_configured;
  std::unique_lock lock(mu_);
  if (!cv_.wait_for(lock, timeout, [&] { return !queue_.empty(); })) return IoStatus::timeout;
  ev = queue_.front();
  queue_.pop_front();
  return IoStatus::ok;
}

IoStatus FakeDigitalIo::set_output(unsigned line, bool value) {
  if (!configured_) return IoStatus::not_configured;
  if (line >= 64) return IoStatus::out_of_range;
  std::lock_guard lock(mu_);
  if (value)
    outputs_ |= (std::uint64_t{1} << line);
  else
    outputs_ &= ~(std::uint64_t{1} << line);
  return IoStatus::ok;
}

void FakeDigitalIo::inject(const EdgeEvent& ev) {
  {
    std::lock_guard lock(mu_);
    queue_.push_back(ev);
  }
  cv_.notify_all();
}

bool FakeDigitalIo::output(unsigned line) const {
  std::lock_guard lock(mu_);
  return line < 64 && (outputs_ >> line) & 1u;
}

}  // namespace errsep::acq

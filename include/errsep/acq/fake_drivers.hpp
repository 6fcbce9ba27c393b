#pragma once
// Fake drivers with fault injection, beside the real ones (ros2_control's mock components), so
// tests and demos exercise the failure paths: a read that fails every Nth time or for good, a
// slow read (missed periods), a stage that faults, sticks or throws on configure, GPIO edges
// injected by the test.
//
// The fakes keep the interfaces' real-time contracts where it matters to the caller: read() is
// noexcept and does not allocate or lock (its value model is a caller-given function, called on
// the sampling thread; keep it allocation-free).
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <string>

#include "errsep/acq/digital_io.hpp"
#include "errsep/acq/displacement_sensor.hpp"
#include "errsep/acq/stage.hpp"

namespace errsep::acq {

/// Faults a FakeSensor injects.  Read counts start at 1 with the first read after configure().
struct FakeSensorFaults {
  std::uint64_t fail_every_n = 0;  ///< every Nth read returns `fail_status` (0 = never)
  std::uint64_t fail_from_read =
      0;  ///< every read from this one on fails (0 = never): a dead sensor
  IoStatus fail_status = IoStatus::timeout;
  std::uint64_t slow_every_n = 0;  ///< every Nth read takes `slow_read` longer (0 = never)
  std::chrono::microseconds slow_read{0};
  std::chrono::microseconds read_time{0};  ///< time every read takes (a bus transaction)
  bool throw_on_configure = false;
};

class FakeSensor final : public DisplacementSensor {
 public:
  /// Value model: µm as a function of the CLOCK_MONOTONIC time of the read.
  using ValueFn = std::function<double(std::int64_t t_ns)>;
  FakeSensor(std::string name, ValueFn value, FakeSensorFaults faults = {});

  const std::string& name() const override { return name_; }
  /// Throws std::runtime_error when throw_on_configure is set.  Not real-time safe.
  void configure() override;
  /// Real-time safe as long as the value model is (sleeps only for injected read times).
  IoStatus read(Sample& out) noexcept override;

  std::uint64_t reads() const noexcept { return reads_.load(std::memory_order_acquire); }
  /// Changes the faults between reads (e.g. a sensor that dies mid-scan).  Not thread-safe
  /// against a concurrent read(); use fail_from_read for that.
  void set_faults(const FakeSensorFaults& f) { faults_ = f; }

 private:
  std::string name_;
  ValueFn value_;
  FakeSensorFaults faults_;
  bool configured_ = false;
  std::atomic<std::uint64_t> reads_{0};
};

/// Faults a FakeStage injects.  Move counts start at 1 with the first move_to().
struct FakeStageFaults {
  std::uint64_t fault_on_move = 0;  ///< that move ends in a drive fault (wait -> fault)
  unsigned fault_code = 0x2310;     ///< fault word reported after the fault
  std::uint64_t stuck_on_move = 0;  ///< that move never arrives (wait -> timeout)
  bool throw_on_configure = false;
};

/// A stage moving at a constant speed with a settling time after arrival.  Thread-safe: the
/// scan thread commands it while sensor value models read its position from the sampler.
class FakeStage final : public Stage {
 public:
  FakeStage(std::string name, double speed_mm_s, std::chrono::milliseconds settle,
            double start_mm = 0.0, FakeStageFaults faults = {});

  const std::string& name() const override { return name_; }
  void configure() override;
  IoStatus move_to(double position_mm) override;
  IoStatus position(double& position_mm) override;
  IoStatus wait_in_position(std::chrono::milliseconds timeout) override;
  IoStatus stop() noexcept override;
  IoStatus fault_code(unsigned& code) override;

  /// Position now, for value models (no status).  Real-time safe (atomics only).
  double position_now_mm() const noexcept;
  std::uint64_t moves() const noexcept { return moves_.load(); }
  std::uint64_t stops() const noexcept { return stops_.load(); }
  bool faulted() const noexcept { return faulted_.load(); }

 private:
  std::string name_;
  double speed_mm_s_;
  std::chrono::milliseconds settle_;
  FakeStageFaults faults_;
  bool configured_ = false;
  // Motion: from_mm at t_start_ns towards target_mm; stuck moves never reach it.
  std::atomic<double> from_mm_, target_mm_;
  std::atomic<std::int64_t> t_start_ns_{0};
  std::atomic<bool> stuck_{false}, faulted_{false}, stopped_{false};
  std::atomic<std::uint64_t> moves_{0}, stops_{0};
};

/// Digital I/O whose input edges are injected by the test.
class FakeDigitalIo final : public DigitalIo {
 public:
  explicit FakeDigitalIo(bool throw_on_configure = false) : throw_(throw_on_configure) {}
  void configure() override;
  IoStatus wait_edge(EdgeEvent& ev, std::chrono::milliseconds timeout) override;
  IoStatus set_output(unsigned line, bool value) override;

  /// Test side: queue an edge (thread-safe).
  void inject(const EdgeEvent& ev);
  /// Last value written to `line` (false if never written).
  bool output(unsigned line) const;

 private:
  bool throw_;
  bool configured_ = false;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::deque<EdgeEvent> queue_;
  std::uint64_t outputs_ = 0;  // bit i = line i (lines < 64)
};

}  // namespace errsep::acq

#pragma once
// One physical Modbus bus (a TCP connection or a serial line) = one libmodbus context.
//
// A libmodbus context is not thread-safe.  The bus guards it with an ownership flag:
//  - read_rt() (the sampling thread) only TRIES to take it and returns at once if another thread
//    holds it: it never waits for a lock (counted as `busy`, reported as IoStatus::timeout);
//  - read()/write()/write_coil() (scan runner, stage commands) and reconnect() (supervisor) wait
//    for it with short sleeps.
// Put stages on their own bus (their own TCP connection) when the sensors are sampled fast, so
// the two never contend; config/simulator.toml does.
//
// libmodbus error recovery stays OFF (MODBUS_ERROR_RECOVERY_LINK can hang for seconds inside a
// call).  A timeout is retried `retries` times after a flush; EPIPE/ECONNRESET/..., or
// kReconnectAfterFailures failed requests in a row, mark the bus "needs reconnect": every later
// request returns IoStatus::disconnected immediately until the BusSupervisor thread has closed,
// re-created and re-connected the context (with bounded exponential back-off).
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "errsep/acq/status.hpp"
#include "errsep/io/machine_config.hpp"

namespace errsep::drivers {

/// Snapshot of a bus's counters (all since construction).
struct BusCounters {
  std::uint64_t requests = 0;     ///< requests started (each retry counts again)
  std::uint64_t ok = 0;           ///< requests answered correctly
  std::uint64_t retries = 0;      ///< retries after a timeout or a garbled answer
  std::uint64_t timeouts = 0;     ///< calls that failed with a timeout after all retries
  std::uint64_t exceptions = 0;   ///< Modbus exception responses
  std::uint64_t disconnects = 0;  ///< times the link was found down (marked for reconnect)
  std::uint64_t reconnects = 0;   ///< successful reconnects
  std::uint64_t reconnect_failures = 0;
  std::uint64_t busy = 0;       ///< read_rt() calls that found the context owned by another thread
  int last_exception_code = 0;  ///< Modbus exception code of the last exception response
  int last_errno = 0;           ///< errno of the last failed libmodbus call
};

class ModbusBus {
 public:
  /// Failed requests in a row (each after its retries) after which the link is reconnected.
  static constexpr int kReconnectAfterFailures = 3;

  explicit ModbusBus(io::BusConfig cfg);
  ~ModbusBus();
  ModbusBus(const ModbusBus&) = delete;
  ModbusBus& operator=(const ModbusBus&) = delete;

  const std::string& name() const noexcept { return cfg_.name; }
  const io::BusConfig& config() const noexcept { return cfg_; }
  /// "tcp 127.0.0.1:1502" or "rtu /dev/ttyUSB0 115200 8N1", for messages.
  std::string describe() const;

  /// Creates the context (response timeout from the config, error recovery off) and connects.
  /// Throws std::runtime_error naming the bus and the endpoint.  Not real-time safe.
  void configure();
  bool configured() const noexcept { return configured_.load(std::memory_order_acquire); }

  /// Reads spec.word_count() registers (input or holding) or one coil into `words`.
  /// Real-time safe: no allocation, never waits for a lock, bounded by
  /// (1 + retries) · response_timeout.
  acq::IoStatus read_rt(const io::RegisterSpec& spec, std::uint16_t* words) noexcept;
  /// The same, waiting for the context if another thread uses it.  Not real-time safe.
  acq::IoStatus read(const io::RegisterSpec& spec, std::uint16_t* words) noexcept;
  /// Writes spec.word_count() holding registers.  Not real-time safe.
  acq::IoStatus write(const io::RegisterSpec& spec, const std::uint16_t* words) noexcept;
  /// Writes one coil.  Not real-time safe.
  acq::IoStatus write_coil(const io::RegisterSpec& spec, bool value) noexcept;

  /// True when the link is down and waits for reconnect().
  bool needs_reconnect() const noexcept { return needs_reconnect_.load(std::memory_order_acquire); }
  /// Closes, frees and re-creates the context and connects once.  Returns true when connected.
  /// Not real-time safe (bounded by the response timeout); called by the BusSupervisor.
  bool reconnect() noexcept;

  BusCounters counters() const noexcept;

 private:
  enum class Op { read, write, write_coil };
  acq::IoStatus transact(Op op, const io::RegisterSpec& spec, std::uint16_t* words, bool wait);
  bool acquire(bool wait) noexcept;
  void release() noexcept { owner_.clear(std::memory_order_release); }
  bool open_context(std::string* why) noexcept;  // caller owns the context
  void mark_down(int err) noexcept;

  io::BusConfig cfg_;
  void* ctx_ = nullptr;  // modbus_t*, kept opaque so <modbus.h> stays in the .cpp
  std::atomic_flag owner_ = ATOMIC_FLAG_INIT;
  std::atomic<bool> configured_{false};
  std::atomic<bool> needs_reconnect_{false};
  int consecutive_failures_ = 0;  // guarded by owner_

  struct AtomicCounters {
    std::atomic<std::uint64_t> requests{0}, ok{0}, retries{0}, timeouts{0}, exceptions{0},
        disconnects{0}, reconnects{0}, reconnect_failures{0}, busy{0};
    std::atomic<int> last_exception_code{0}, last_errno{0};
  } c_;
};

struct SupervisorOptions {
  std::chrono::milliseconds poll{20};             ///< how often the buses are checked
  std::chrono::milliseconds initial_backoff{50};  ///< wait before the 2nd attempt ...
  std::chrono::milliseconds max_backoff{2000};    ///< ... doubling up to this
};

/// Reconnects buses marked "needs reconnect", off the real-time path, with bounded exponential
/// back-off.  start() launches its thread; stop() (and the destructor) joins it.
class BusSupervisor {
 public:
  explicit BusSupervisor(std::vector<ModbusBus*> buses, SupervisorOptions opts = {});
  ~BusSupervisor();
  BusSupervisor(const BusSupervisor&) = delete;
  BusSupervisor& operator=(const BusSupervisor&) = delete;
  void start();
  void stop() noexcept;
  bool running() const noexcept { return thread_.joinable(); }

 private:
  void loop();
  std::vector<ModbusBus*> buses_;
  SupervisorOptions opts_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace errsep::drivers

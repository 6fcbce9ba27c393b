#include "errsep/drivers/modbus_bus.hpp"

#include <modbus.h>

#include <algorithm>
#include <cerrno>
#include <stdexcept>

namespace errsep::drivers {
namespace {

modbus_t* mb(void* p) {
  return static_cast<modbus_t*>(p);
}

bool is_exception(int err) {
  return err >= EMBXILFUN && err <= EMBXGTAR;
}

// Errors after which the context is useless until closed and re-created (NOTES.md: after a peer
// reboot a context can return EPIPE on every call).
bool is_link_down(int err) {
  switch (err) {
    case EPIPE:
    case ECONNRESET:
    case ENOTCONN:
    case EBADF:
    case ECONNREFUSED:
    case ECONNABORTED:
    case ENETDOWN:
    case ENETUNREACH:
    case EHOSTUNREACH:
    case EIO:
      return true;
    default:
      return false;
  }
}

}  // namespace

ModbusBus::ModbusBus(io::BusConfig cfg) : cfg_(std::move(cfg)) {}

ModbusBus::~ModbusBus() {
  if (ctx_) {
    modbus_close(mb(ctx_));
    modbus_free(mb(ctx_));
  }
}

std::string ModbusBus::describe() const {
  if (cfg_.kind == io::BusKind::tcp) return "tcp " + cfg_.host + ":" + std::to_string(cfg_.port);
  const char p = cfg_.parity == io::Parity::none   ? 'N'
                 : cfg_.parity == io::Parity::even ? 'E'
                                                   : 'O';
  return "rtu " + cfg_.device + " " + std::to_string(cfg_.baud) + " " +
         std::to_string(cfg_.data_bits) + p + std::to_string(cfg_.stop_bits);
}

bool ModbusBus::open_context(std::string* why) noexcept {
  if (ctx_) {
    modbus_close(mb(ctx_));
    modbus_free(mb(ctx_));
    ctx_ = nullptr;
  }
  modbus_t* ctx = nullptr;
  if (cfg_.kind == io::BusKind::tcp) {
    // _pi accepts IPv4, IPv6 (::1) and host names.
    ctx = modbus_new_tcp_pi(cfg_.host.c_str(), std::to_string(cfg_.port).c_str());
  } else {
    const char p = cfg_.parity == io::Parity::none   ? 'N'
                   : cfg_.parity == io::Parity::even ? 'E'
                                                     : 'O';
    ctx = modbus_new_rtu(cfg_.device.c_str(), cfg_.baud, p, cfg_.data_bits, cfg_.stop_bits);
  }
  if (!ctx) {
    if (why) *why = std::string("cannot create the libmodbus context: ") + modbus_strerror(errno);
    return false;
  }
  // Error recovery off: libmodbus's link recovery can hang for seconds inside a call; the
  // supervisor reconnects instead (NOTES.md, libmodbus docs/modbus_set_error_recovery.md).
  modbus_set_error_recovery(ctx, MODBUS_ERROR_RECOVERY_NONE);
  const auto ms = static_cast<std::uint32_t>(cfg_.response_timeout_ms);
  modbus_set_response_timeout(ctx, ms / 1000, (ms % 1000) * 1000);
  modbus_set_byte_timeout(ctx, ms / 1000, (ms % 1000) * 1000);
  if (modbus_connect(ctx) == -1) {
    const int err = errno;
    if (why) *why = std::string("cannot connect: ") + modbus_strerror(err);
    c_.last_errno.store(err, std::memory_order_relaxed);
    modbus_free(ctx);
    return false;
  }
  ctx_ = ctx;
  return true;
}

void ModbusBus::configure() {
  if (!acquire(true))
    throw std::runtime_error("bus '" + cfg_.name + "': context busy during configure");
  std::string why;
  const bool ok = open_context(&why);
  consecutive_failures_ = 0;
  release();
  if (!ok)
    throw std::runtime_error("bus '" + cfg_.name + "' (" + describe() + "): " + why +
                             (cfg_.kind == io::BusKind::tcp
                                  ? " (is the device or errsep-devsim running on that port?)"
                                  : " (check the device path, permissions and line settings)"));
  needs_reconnect_.store(false, std::memory_order_release);
  configured_.store(true, std::memory_order_release);
}

bool ModbusBus::acquire(bool wait) noexcept {
  if (!owner_.test_and_set(std::memory_order_acquire)) return true;
  if (!wait) return false;
  // Another thread holds the context for at most one request with its retries.
  const auto limit =
      std::chrono::milliseconds(std::max(2000, 4 * (1 + cfg_.retries) * cfg_.response_timeout_ms));
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (owner_.test_and_set(std::memory_order_acquire)) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::microseconds(50));
  }
  return true;
}

void ModbusBus::mark_down(int err) noexcept {
  c_.last_errno.store(err, std::memory_order_relaxed);
  if (!needs_reconnect_.exchange(true, std::memory_order_acq_rel))
    c_.disconnects.fetch_add(1, std::memory_order_relaxed);
}

acq::IoStatus ModbusBus::transact(Op op, const io::RegisterSpec& spec, std::uint16_t* words,
                                  bool wait) {
  using acq::IoStatus;
  if (!configured_.load(std::memory_order_acquire)) return IoStatus::not_configured;
  if (needs_reconnect_.load(std::memory_order_acquire)) return IoStatus::disconnected;
  if (!acquire(wait)) {
    c_.busy.fetch_add(1, std::memory_order_relaxed);
    return IoStatus::timeout;
  }
  struct Release {
    ModbusBus* b;
    ~Release() { b->release(); }
  } guard{this};
  if (!ctx_ || needs_reconnect_.load(std::memory_order_acquire)) return IoStatus::disconnected;

  modbus_t* ctx = mb(ctx_);
  modbus_set_slave(ctx, spec.unit_id);
  const int n = spec.word_count();
  for (int attempt = 0; attempt <= cfg_.retries; ++attempt) {
    if (attempt > 0) {
      c_.retries.fetch_add(1, std::memory_order_relaxed);
      // A late answer to the previous attempt would be taken for this one's: discard it.
      modbus_flush(ctx);
    }
    c_.requests.fetch_add(1, std::memory_order_relaxed);
    int rc = -1;
    switch (op) {
      case Op::read:
        if (spec.kind == io::RegisterKind::coil) {
          std::uint8_t bit = 0;
          rc = modbus_read_bits(ctx, spec.address, 1, &bit);
          words[0] = bit;
        } else if (spec.kind == io::RegisterKind::input) {
          rc = modbus_read_input_registers(ctx, spec.address, n, words);
        } else {
          rc = modbus_read_registers(ctx, spec.address, n, words);
        }
        break;
      case Op::write:
        rc = n == 1 ? modbus_write_register(ctx, spec.address, words[0])
                    : modbus_write_registers(ctx, spec.address, n, words);
        break;
      case Op::write_coil:
        rc = modbus_write_bit(ctx, spec.address, words[0] != 0 ? 1 : 0);
        break;
    }
    if (rc != -1) {
      c_.ok.fetch_add(1, std::memory_order_relaxed);
      consecutive_failures_ = 0;
      return IoStatus::ok;
    }
    const int err = errno;
    c_.last_errno.store(err, std::memory_order_relaxed);
    if (is_exception(err)) {
      // The device is there and answered: no retry, no reconnect.
      c_.exceptions.fetch_add(1, std::memory_order_relaxed);
      c_.last_exception_code.store(err - MODBUS_ENOBASE, std::memory_order_relaxed);
      consecutive_failures_ = 0;
      return IoStatus::device_exception;
    }
    if (is_link_down(err)) {
      mark_down(err);
      return IoStatus::disconnected;
    }
    // ETIMEDOUT, or a garbled/mismatched answer (EMBBADDATA, EMBBADCRC, ...): retry.
  }
  c_.timeouts.fetch_add(1, std::memory_order_relaxed);
  if (++consecutive_failures_ >= kReconnectAfterFailures) mark_down(ETIMEDOUT);
  return IoStatus::timeout;
}

acq::IoStatus ModbusBus::read_rt(const io::RegisterSpec& spec, std::uint16_t* words) noexcept {
  return transact(Op::read, spec, words, false);
}

acq::IoStatus ModbusBus::read(const io::RegisterSpec& spec, std::uint16_t* words) noexcept {
  return transact(Op::read, spec, words, true);
}

acq::IoStatus ModbusBus::write(const io::RegisterSpec& spec, const std::uint16_t* words) noexcept {
  std::uint16_t w[2] = {words[0], spec.word_count() > 1 ? words[1] : std::uint16_t{0}};
  return transact(Op::write, spec, w, true);
}

acq::IoStatus ModbusBus::write_coil(const io::RegisterSpec& spec, bool value) noexcept {
  std::uint16_t w[1] = {static_cast<std::uint16_t>(value ? 1 : 0)};
  return transact(Op::write_coil, spec, w, true);
}

bool ModbusBus::reconnect() noexcept {
  if (!acquire(true)) return false;
  const bool ok = open_context(nullptr);
  consecutive_failures_ = 0;
  if (ok) {
    needs_reconnect_.store(false, std::memory_order_release);
    configured_.store(true, std::memory_order_release);
    c_.reconnects.fetch_add(1, std::memory_order_relaxed);
  } else {
    needs_reconnect_.store(true, std::memory_order_release);
    c_.reconnect_failures.fetch_add(1, std::memory_order_relaxed);
  }
  release();
  return ok;
}

BusCounters ModbusBus::counters() const noexcept {
  BusCounters b;
  b.requests = c_.requests.load(std::memory_order_relaxed);
  b.ok = c_.ok.load(std::memory_order_relaxed);
  b.retries = c_.retries.load(std::memory_order_relaxed);
  b.timeouts = c_.timeouts.load(std::memory_order_relaxed);
  b.exceptions = c_.exceptions.load(std::memory_order_relaxed);
  b.disconnects = c_.disconnects.load(std::memory_order_relaxed);
  b.reconnects = c_.reconnects.load(std::memory_order_relaxed);
  b.reconnect_failures = c_.reconnect_failures.load(std::memory_order_relaxed);
  b.busy = c_.busy.load(std::memory_order_relaxed);
  b.last_exception_code = c_.last_exception_code.load(std::memory_order_relaxed);
  b.last_errno = c_.last_errno.load(std::memory_order_relaxed);
  return b;
}

// --- supervisor --------------------------------------------------------------------------

BusSupervisor::BusSupervisor(std::vector<ModbusBus*> buses, SupervisorOptions opts)
    : buses_(std::move(buses)), opts_(opts) {}

BusSupervisor::~BusSupervisor() {
  stop();
}

void BusSupervisor::start() {
  if (thread_.joinable()) return;
  stop_.store(false);
  thread_ = std::thread([this] { loop(); });
}

void BusSupervisor::stop() noexcept {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

void BusSupervisor::loop() {
  using clock = std::chrono::steady_clock;
  struct State {
    clock::time_point next{};
    std::chrono::milliseconds backoff{0};
  };
  std::vector<State> st(buses_.size());
  for (auto& s : st)
    s.backoff = opts_.initial_backoff;
  while (!stop_.load()) {
    const auto now = clock::now();
    for (std::size_t i = 0; i < buses_.size(); ++i) {
      ModbusBus* b = buses_[i];
      if (!b->needs_reconnect() || now < st[i].next) continue;
      if (b->reconnect()) {
        st[i].backoff = opts_.initial_backoff;
        st[i].next = {};
      } else {
        st[i].next = clock::now() + st[i].backoff;
        st[i].backoff = std::min(opts_.max_backoff, st[i].backoff * 2);
      }
    }
    std::this_thread::sleep_for(opts_.poll);
  }
}

}  // namespace errsep::drivers

#include "errsep/drivers/modbus_tcp_server.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <modbus.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <mutex>
#include <stdexcept>
#include <vector>

namespace errsep::drivers {

bool ModbusTcpServerOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (host.empty()) return fail("modbus host: must not be empty");
  if (port < 0 || port > 65535)
    return fail("modbus port = " + std::to_string(port) + ": must be in [0, 65535]");
  if (max_connections < 1 || max_connections > 4096)
    return fail("max_connections = " + std::to_string(max_connections) + ": must be in [1, 4096]");
  if (idle_timeout_ms < 1)
    return fail("idle_timeout_ms = " + std::to_string(idle_timeout_ms) + ": must be > 0");
  if (frame_timeout_ms < 1)
    return fail("frame_timeout_ms = " + std::to_string(frame_timeout_ms) + ": must be > 0");
  if (backlog < 1) return fail("backlog = " + std::to_string(backlog) + ": must be > 0");
  return true;
}

namespace {

using clk = std::chrono::steady_clock;

constexpr int kMbapLength = 7;  // transaction id, protocol id, length, unit id
constexpr auto kTick = std::chrono::milliseconds(10);
constexpr int kRequestsPerWakeup = 16;  // one client's pipelined requests served per poll

struct Connection {
  int fd = -1;
  std::array<std::uint8_t, MODBUS_TCP_MAX_ADU_LENGTH> buf{};
  int have = 0;                  // bytes of the request gathered so far
  clk::time_point last_request;  // accept or last complete request: idleness
  clk::time_point frame_start;   // first byte of the request being gathered
};

// Bytes the request in `c` needs in all, or -1 when its header is not Modbus TCP.
int needed(const Connection& c) {
  if (c.have < kMbapLength) return kMbapLength;
  const int protocol = (c.buf[2] << 8) | c.buf[3];
  const int length = (c.buf[4] << 8) | c.buf[5];  // unit id + PDU
  if (protocol != 0 || length < 2 || 6 + length > MODBUS_TCP_MAX_ADU_LENGTH) return -1;
  return 6 + length;
}

}  // namespace

struct ModbusTcpServer::Impl {
  modbus_t* ctx = nullptr;
  int listen_fd = -1;
  std::vector<Connection> conns;
  // The counters and the open count change together under one lock, so that a snapshot taken
  // from another thread always accounts for every connection admitted (a closing counted but
  // not yet removed read as both open and closed).  The serving thread is not the sampling
  // thread; it takes the lock once per connection event or request.
  mutable std::mutex mu;
  ModbusTcpServerStats counts;

  ~Impl() {
    close_all();
    if (listen_fd >= 0) ::close(listen_fd);
    if (ctx) modbus_free(ctx);
  }
  void count(std::uint64_t ModbusTcpServerStats::*counter) {
    const std::lock_guard lock(mu);
    ++(counts.*counter);
  }
  /// Closes conns[i] and counts why, in one step.
  void close_at(std::size_t i, std::uint64_t ModbusTcpServerStats::*reason) {
    ::close(conns[i].fd);
    conns.erase(conns.begin() + static_cast<std::ptrdiff_t>(i));
    const std::lock_guard lock(mu);
    ++(counts.*reason);
    counts.connections = static_cast<int>(conns.size());
  }
  void admit(const Connection& c) {
    conns.push_back(c);
    const std::lock_guard lock(mu);
    ++counts.accepted;
    counts.connections = static_cast<int>(conns.size());
  }
  /// Closes every connection (on a handler's request, or at the end of run()): the server's own
  /// close, counted under no reason (as before this lock was added).
  void close_all() {
    for (const auto& c : conns)
      ::close(c.fd);
    conns.clear();
    const std::lock_guard lock(mu);
    counts.connections = 0;
  }
};

ModbusTcpServer::ModbusTcpServer(std::string what, ModbusTcpServerOptions opts, Handler handler)
    : impl_(std::make_unique<Impl>()),
      what_(std::move(what)),
      opts_(std::move(opts)),
      handler_(std::move(handler)) {
  std::string why;
  if (!opts_.is_valid(&why)) throw std::invalid_argument(what_ + ": " + why);
}

ModbusTcpServer::~ModbusTcpServer() = default;

int ModbusTcpServer::listen() {
  Impl& m = *impl_;
  const std::string service = std::to_string(opts_.port);
  m.ctx = modbus_new_tcp_pi(opts_.host.c_str(), service.c_str());
  if (!m.ctx)
    throw std::runtime_error(what_ + ": cannot create a Modbus TCP context for " + opts_.host +
                             ":" + service + ": " + modbus_strerror(errno));
  m.listen_fd = modbus_tcp_pi_listen(m.ctx, opts_.backlog);
  if (m.listen_fd < 0)
    throw std::runtime_error(what_ + ": cannot listen on " + opts_.host + " port " + service +
                             ": " + modbus_strerror(errno) + " (another process on that port?)");
  // Accept in a loop until EAGAIN: the listening socket must not block either.
  const int fl = fcntl(m.listen_fd, F_GETFL);
  if (fl < 0 || fcntl(m.listen_fd, F_SETFL, fl | O_NONBLOCK) != 0)
    throw std::runtime_error(what_ + ": fcntl O_NONBLOCK: " + std::strerror(errno));
  sockaddr_storage addr{};
  socklen_t len = sizeof addr;
  if (getsockname(m.listen_fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0)
    throw std::runtime_error(what_ + ": getsockname: " + std::strerror(errno));
  port_ = addr.ss_family == AF_INET6 ? ntohs(reinterpret_cast<sockaddr_in6*>(&addr)->sin6_port)
                                     : ntohs(reinterpret_cast<sockaddr_in*>(&addr)->sin_port);
  return port_;
}

void ModbusTcpServer::run(const std::atomic<bool>& stop) {
  Impl& m = *impl_;
  if (m.listen_fd < 0) throw std::logic_error(what_ + ": run() before listen()");
  const auto idle_limit = std::chrono::milliseconds(opts_.idle_timeout_ms);
  const auto frame_limit = std::chrono::milliseconds(opts_.frame_timeout_ms);
  const auto max_conns = static_cast<std::size_t>(opts_.max_connections);
  std::vector<pollfd> pfds;
  while (!stop.load(std::memory_order_relaxed)) {
    pfds.clear();
    pfds.push_back({m.listen_fd, POLLIN, 0});
    for (const auto& c : m.conns)
      pfds.push_back({c.fd, POLLIN, 0});
    const int n = ::poll(pfds.data(), pfds.size(), static_cast<int>(kTick.count()));
    if (n < 0) {
      if (errno == EINTR) continue;
      throw std::runtime_error(what_ + ": poll: " + std::strerror(errno));
    }
    const auto now = clk::now();

    // Serve the clients polled (indices of pfds match conns before any change this round:
    // walk by fd, since a handler may close every connection).
    std::vector<int> ready;
    for (std::size_t k = 1; k < pfds.size(); ++k)
      if (pfds[k].revents != 0) ready.push_back(pfds[k].fd);
    for (int fd : ready) {
      auto it = std::find_if(m.conns.begin(), m.conns.end(),
                             [fd](const Connection& c) { return c.fd == fd; });
      if (it == m.conns.end()) continue;
      auto idx = static_cast<std::size_t>(it - m.conns.begin());
      std::uint64_t ModbusTcpServerStats::*closed_for = nullptr;
      bool close_all = false;
      for (int served = 0; served < kRequestsPerWakeup && !closed_for;) {
        Connection& c = m.conns[idx];
        const int want = needed(c);
        if (want < 0) {
          closed_for = &ModbusTcpServerStats::malformed;
          break;
        }
        const ssize_t got =
            ::recv(c.fd, c.buf.data() + c.have, static_cast<std::size_t>(want - c.have), 0);
        if (got == 0 || (got < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)) {
          closed_for = &ModbusTcpServerStats::closed_by_peer;
          break;
        }
        if (got < 0) break;  // nothing more now: keep what was gathered
        if (c.have == 0) c.frame_start = now;
        c.have += static_cast<int>(got);
        if (c.have < kMbapLength || c.have < needed(c)) continue;
        // A whole request: to the handler, with the rest of the buffer zeroed so that a
        // request whose counts disagree with its length reads zeros, not an older request.
        const int length = c.have;
        c.have = 0;
        c.last_request = now;
        ++served;
        m.count(&ModbusTcpServerStats::requests);
        modbus_set_socket(m.ctx, c.fd);
        const auto action = handler_(m.ctx, c.buf.data(), length);
        std::fill(c.buf.begin(), c.buf.end(), std::uint8_t{0});
        if (action == ModbusConnectionAction::close_all) {
          close_all = true;
          break;
        }
        if (action == ModbusConnectionAction::close)
          closed_for = &ModbusTcpServerStats::send_failures;
      }
      if (close_all) {
        m.close_all();
        break;
      }
      if (closed_for) m.close_at(idx, closed_for);
    }

    // Time-outs, only of connections with nothing waiting to be read: bytes that have come are
    // served first, so a server thread that was not scheduled for a while closes no client
    // whose request was already there.
    for (std::size_t i = m.conns.size(); i-- > 0;) {
      const Connection& c = m.conns[i];
      if (std::find(ready.begin(), ready.end(), c.fd) != ready.end()) continue;
      if (c.have > 0 && now - c.frame_start > frame_limit) {
        m.close_at(i, &ModbusTcpServerStats::frame_timeouts);
      } else if (c.have == 0 && now - c.last_request > idle_limit) {
        m.close_at(i, &ModbusTcpServerStats::idle_timeouts);
      }
    }

    if (pfds[0].revents & POLLIN) {
      for (;;) {
        const int fd = ::accept4(m.listen_fd, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
        if (fd < 0) break;  // EAGAIN: none left (other errors: the client gave up)
        if (m.conns.size() >= max_conns) {
          // Evict the connection longest without a complete request (idle, or stuck in a frame).
          const auto oldest = std::min_element(m.conns.begin(), m.conns.end(),
                                               [](const Connection& a, const Connection& b) {
                                                 return a.last_request < b.last_request;
                                               });
          m.close_at(static_cast<std::size_t>(oldest - m.conns.begin()),
                     &ModbusTcpServerStats::evictions);
        }
        Connection c;
        c.fd = fd;
        c.last_request = now;
        m.admit(c);
      }
    }
  }
  m.close_all();
}

ModbusTcpServerStats ModbusTcpServer::stats() const noexcept {
  const std::lock_guard lock(impl_->mu);
  return impl_->counts;
}

}  // namespace errsep::drivers

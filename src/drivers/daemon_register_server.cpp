#include "errsep/drivers/daemon_register_server.hpp"

#include <arpa/inet.h>
#include <modbus.h>
#include <netinet/in.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <vector>

namespace errsep::drivers {

bool RegisterServerOptions::is_valid(std::string* why) const {
  if (port < 0 || port > 65535) {
    if (why) *why = "modbus port = " + std::to_string(port) + ": must be in [0, 65535]";
    return false;
  }
  if (host.empty()) {
    if (why) *why = "modbus host: must not be empty";
    return false;
  }
  return true;
}

struct DaemonRegisterServer::Impl {
  modbus_t* ctx = nullptr;
  modbus_mapping_t* map = nullptr;
  int listen_fd = -1;
  std::vector<int> clients;
  std::chrono::steady_clock::time_point t0 = std::chrono::steady_clock::now();
  ~Impl() {
    for (int fd : clients)
      ::close(fd);
    if (listen_fd >= 0) ::close(listen_fd);
    if (map) modbus_mapping_free(map);
    if (ctx) modbus_free(ctx);
  }
};

DaemonRegisterServer::DaemonRegisterServer(acq::Daemon& daemon, RegisterServerOptions opts)
    : impl_(std::make_unique<Impl>()), daemon_(daemon), opts_(std::move(opts)) {
  std::string why;
  if (!opts_.is_valid(&why)) throw std::invalid_argument("register map: " + why);
}

DaemonRegisterServer::~DaemonRegisterServer() {
  stop();
}

int DaemonRegisterServer::listen() {
  Impl& m = *impl_;
  const std::string service = std::to_string(opts_.port);
  m.ctx = modbus_new_tcp_pi(opts_.host.c_str(), service.c_str());
  if (!m.ctx)
    throw std::runtime_error("register map: cannot create a Modbus TCP context for " + opts_.host +
                             ":" + service + ": " + modbus_strerror(errno));
  m.listen_fd = modbus_tcp_pi_listen(m.ctx, 8);
  if (m.listen_fd < 0)
    throw std::runtime_error("register map: cannot listen on " + opts_.host + " port " + service +
                             ": " + modbus_strerror(errno) +
                             " (another process on that port? choose another with --modbus-port)");
  sockaddr_storage addr{};
  socklen_t len = sizeof addr;
  if (getsockname(m.listen_fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0)
    throw std::runtime_error(std::string("register map: getsockname: ") + std::strerror(errno));
  port_ = addr.ss_family == AF_INET6 ? ntohs(reinterpret_cast<sockaddr_in6*>(&addr)->sin6_port)
                                     : ntohs(reinterpret_cast<sockaddr_in*>(&addr)->sin_port);
  m.map = modbus_mapping_new_start_address(0, 2, 0, 0, 0, 0, 0, kInputRegisterCount);
  if (!m.map) throw std::runtime_error(std::string("register map: ") + modbus_strerror(errno));
  return port_;
}

void DaemonRegisterServer::start() {
  if (impl_->listen_fd < 0) throw std::logic_error("register map: start() before listen()");
  stop_.store(false);
  thread_ = std::thread([this] { loop(); });
}

void DaemonRegisterServer::stop() noexcept {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

namespace {

// um as int32 nm, high word first; INT32_MIN when there is no value.
void put_nm(std::uint16_t* r, double um) {
  std::int32_t nm = std::numeric_limits<std::int32_t>::min();
  if (std::isfinite(um) && std::abs(um) < 2.0e6)
    nm = static_cast<std::int32_t>(std::lround(um * 1000.0));
  const auto u = static_cast<std::uint32_t>(nm);
  r[0] = static_cast<std::uint16_t>(u >> 16);
  r[1] = static_cast<std::uint16_t>(u & 0xFFFF);
}

void fill(modbus_mapping_t* map, const acq::DaemonStatus& s, std::uint16_t alive) {
  std::uint16_t* r = map->tab_input_registers;
  r[0] = static_cast<std::uint16_t>(s.state);
  r[1] = static_cast<std::uint16_t>(s.last_trigger);
  r[2] = static_cast<std::uint16_t>(s.scan_id & 0xFFFF);
  r[3] = static_cast<std::uint16_t>(std::min<std::uint32_t>(s.points_done, 0xFFFF));
  r[4] = static_cast<std::uint16_t>(std::min<std::uint32_t>(s.points_total, 0xFFFF));
  r[5] = static_cast<std::uint16_t>(s.scans_completed & 0xFFFF);
  r[6] = static_cast<std::uint16_t>(s.last_scan_id & 0xFFFF);
  r[7] = static_cast<std::uint16_t>(s.last_outcome);
  put_nm(r + 8, s.last_straightness_um);
  r[10] = static_cast<std::uint16_t>(s.faults & 0xFFFF);
  r[11] = alive;
  r[12] = kRegisterMapVersion;
  r[13] = static_cast<std::uint16_t>(s.last_trigger_source);
  put_nm(r + 14, s.last_straightness_lsq_um);
  put_nm(r + 16, s.last_straightness_U_um);
  map->tab_bits[0] = map->tab_bits[1] = 0;
}

}  // namespace

void DaemonRegisterServer::loop() {
  Impl& m = *impl_;
  while (!stop_.load(std::memory_order_relaxed)) {
    fd_set rd;
    FD_ZERO(&rd);
    FD_SET(m.listen_fd, &rd);
    int maxfd = m.listen_fd;
    for (int fd : m.clients) {
      FD_SET(fd, &rd);
      maxfd = std::max(maxfd, fd);
    }
    timeval tv{0, 50000};  // notices stop() within 50 ms; idle otherwise (no spinning)
    const int n = select(maxfd + 1, &rd, nullptr, nullptr, &tv);
    if (n <= 0) continue;
    if (FD_ISSET(m.listen_fd, &rd)) {
      const int fd = ::accept4(m.listen_fd, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd >= 0) {
        if (fd >= FD_SETSIZE || m.clients.size() >= 16)
          ::close(fd);
        else
          m.clients.push_back(fd);
      }
    }
    const std::vector<int> ready = m.clients;
    for (int fd : ready) {
      if (!FD_ISSET(fd, &rd)) continue;
      std::uint8_t q[MODBUS_TCP_MAX_ADU_LENGTH];
      modbus_set_socket(m.ctx, fd);
      const int rc = modbus_receive(m.ctx, q);
      bool keep = rc >= 0;
      if (rc > 0) {
        const auto alive =
            static_cast<std::uint16_t>(std::chrono::duration_cast<std::chrono::seconds>(
                                           std::chrono::steady_clock::now() - m.t0)
                                           .count() &
                                       0xFFFF);
        fill(m.map, daemon_.status(), alive);
        const int h = modbus_get_header_length(m.ctx);
        const int fc = q[h];
        const int addr = (q[h + 1] << 8) | q[h + 2];
        // Coil writes: which coils are set to 1 by this request?
        bool start = false, abort = false, coil_write = false;
        if (fc == MODBUS_FC_WRITE_SINGLE_COIL && rc >= h + 5) {
          coil_write = true;
          const bool on = q[h + 3] == 0xFF && q[h + 4] == 0x00;
          start = on && addr == 0;
          abort = on && addr == 1;
        } else if (fc == MODBUS_FC_WRITE_MULTIPLE_COILS && rc >= h + 6) {
          coil_write = true;
          const int count = (q[h + 3] << 8) | q[h + 4];
          for (int k = 0; k < count && 6 + k / 8 < rc - h; ++k) {
            const bool on = (q[h + 6 + k / 8] >> (k % 8)) & 1;
            if (on && addr + k == 0) start = true;
            if (on && addr + k == 1) abort = true;
          }
        }
        bool refused = false;
        if (coil_write) {
          if (abort) daemon_.abort_scan();
          if (start)
            refused = daemon_.trigger(acq::TriggerSource::modbus) != acq::TriggerReply::accepted;
        }
        if (refused) {
          keep = modbus_reply_exception(m.ctx, q, MODBUS_EXCEPTION_SLAVE_OR_SERVER_BUSY) >= 0;
        } else {
          keep = modbus_reply(m.ctx, q, rc, m.map) >= 0;
        }
        m.map->tab_bits[0] = m.map->tab_bits[1] = 0;  // momentary
      }
      if (!keep) {
        ::close(fd);
        m.clients.erase(std::find(m.clients.begin(), m.clients.end(), fd));
      }
    }
  }
}

}  // namespace errsep::drivers

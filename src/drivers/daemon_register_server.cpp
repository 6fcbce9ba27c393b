#include "errsep/drivers/daemon_register_server.hpp"

#include <modbus.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace errsep::drivers {

struct DaemonRegisterServer::Impl {
  modbus_mapping_t* map = nullptr;
  std::chrono::steady_clock::time_point t0 = std::chrono::steady_clock::now();
  std::unique_ptr<ModbusTcpServer> server;
  ~Impl() {
    server.reset();  // its sockets and context first
    if (map) modbus_mapping_free(map);
  }
};

DaemonRegisterServer::DaemonRegisterServer(acq::Daemon& daemon, RegisterServerOptions opts)
    : impl_(std::make_unique<Impl>()), daemon_(daemon) {
  impl_->server = std::make_unique<ModbusTcpServer>(
      "register map", std::move(opts),
      [this](_modbus* ctx, const std::uint8_t* q, int length) { return handle(ctx, q, length); });
}

DaemonRegisterServer::~DaemonRegisterServer() {
  stop();
}

int DaemonRegisterServer::listen() {
  Impl& m = *impl_;
  m.map = modbus_mapping_new_start_address(0, 2, 0, 0, 0, 0, 0, kInputRegisterCount);
  if (!m.map) throw std::runtime_error(std::string("register map: ") + modbus_strerror(errno));
  try {
    return m.server->listen();
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(std::string(e.what()) + " (choose another with --modbus-port)");
  }
}

int DaemonRegisterServer::port() const noexcept {
  return impl_->server->port();
}

ModbusTcpServerStats DaemonRegisterServer::stats() const noexcept {
  return impl_->server->stats();
}

void DaemonRegisterServer::start() {
  if (impl_->server->port() <= 0) throw std::logic_error("register map: start() before listen()");
  stop_.store(false);
  thread_ = std::thread([this] { impl_->server->run(stop_); });
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

ModbusConnectionAction DaemonRegisterServer::handle(_modbus* ctx, const std::uint8_t* q, int rc) {
  Impl& m = *impl_;
  const auto alive = static_cast<std::uint16_t>(
      std::chrono::duration_cast<std::chrono::seconds>(std::chrono::steady_clock::now() - m.t0)
          .count() &
      0xFFFF);
  fill(m.map, daemon_.status(), alive);
  const int h = modbus_get_header_length(ctx);
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
    if (start) refused = daemon_.trigger(acq::TriggerSource::modbus) != acq::TriggerReply::accepted;
  }
  const int sent = refused ? modbus_reply_exception(ctx, q, MODBUS_EXCEPTION_SLAVE_OR_SERVER_BUSY)
                           : modbus_reply(ctx, q, rc, m.map);
  m.map->tab_bits[0] = m.map->tab_bits[1] = 0;  // momentary
  return sent >= 0 ? ModbusConnectionAction::keep : ModbusConnectionAction::close;
}

}  // namespace errsep::drivers

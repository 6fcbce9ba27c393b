// The shared Modbus TCP server loop (drivers/modbus_tcp_server.hpp) under a misbehaving load, as
// a stuck HMI or a port scanner would make it: 200 connections opened and left idle, then 20
// half-open ones (the first 9 bytes of a 12-byte request, then silence), all on 127.0.0.1 at an
// ephemeral port.  A legitimate client must still be served within 1 s:
//  - the daemon's register map (errsep::acq::Daemon in-process, its start coil written by mbpoll
//    as the cell controller would): the scan starts;
//  - the device simulator: a sensor register is read (mbpoll).
// Then the half-open connections are closed by the frame time-out and the idle ones by the idle
// time-out, and every connection admitted is accounted for in the server's stats.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <thread>
#include <vector>

#include "errsep/acq/daemon.hpp"
#include "errsep/drivers/daemon_register_server.hpp"
#include "errsep/drivers/modbus_device_simulator.hpp"
#include "errsep/drivers/modbus_tcp_server.hpp"
#include "errsep/io/machine_config.hpp"
#include "support/daemon_rig.hpp"
#include "support/support.hpp"

using namespace errsep;
using namespace std::chrono_literals;
using clk = std::chrono::steady_clock;

namespace {

constexpr int kIdle = 200;
constexpr int kHalfOpen = 20;

/// Client sockets of the misbehaving load, closed on destruction.
struct Load {
  std::vector<int> fds;
  Load() = default;
  Load(const Load&) = delete;
  Load& operator=(const Load&) = delete;
  ~Load() {
    for (int fd : fds)
      ::close(fd);
  }
  int connect(int port) {
    const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) return -1;
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
      ::close(fd);
      return -1;
    }
    fds.push_back(fd);
    return fd;
  }
  /// kIdle idle connections, then kHalfOpen that send 9 of the 12 bytes of a request (read one
  /// input register of unit 1) and go silent.  Returns the connections made.
  int open(int port) {
    int made = 0;
    for (int i = 0; i < kIdle; ++i)
      made += connect(port) >= 0;
    const std::uint8_t partial[9] = {0x00, 0x01, 0x00, 0x00, 0x00, 0x06, 0x01, 0x04, 0x00};
    for (int i = 0; i < kHalfOpen; ++i) {
      const int fd = connect(port);
      if (fd >= 0 && ::send(fd, partial, sizeof partial, MSG_NOSIGNAL) == sizeof partial) ++made;
    }
    return made;
  }
};

template <class Pred>
bool eventually(Pred pred, std::chrono::milliseconds limit) {
  const auto until = clk::now() + limit;
  while (clk::now() < until) {
    if (pred()) return true;
    std::this_thread::sleep_for(5ms);
  }
  return pred();
}

/// Every connection admitted is open or was closed for exactly one counted reason.
void check_accounted(const drivers::ModbusTcpServerStats& s) {
  CHECK(s.accepted == static_cast<std::uint64_t>(s.connections) + s.evictions + s.idle_timeouts +
                          s.frame_timeouts + s.closed_by_peer + s.malformed + s.send_failures);
}

void print(const char* what, double ms, const drivers::ModbusTcpServerStats& s) {
  std::fprintf(stderr,
               "%s: served in %.0f ms under load; accepted %llu, evictions %llu, idle time-outs "
               "%llu, frame time-outs %llu, open %d\n",
               what, ms, static_cast<unsigned long long>(s.accepted),
               static_cast<unsigned long long>(s.evictions),
               static_cast<unsigned long long>(s.idle_timeouts),
               static_cast<unsigned long long>(s.frame_timeouts), s.connections);
}

double ms_since(clk::time_point t0) {
  return std::chrono::duration<double, std::milli>(clk::now() - t0).count();
}

/// A backend whose scan lays out a small four-sensor scan and runs until aborted: the test
/// needs only to see that the start coil started it.
class WaitingBackend final : public acq::ScanBackend {
 public:
  void open() override {}
  bool check(std::string*) override { return true; }
  acq::ScanEnd run_scan(acq::ScanContext& ctx) override {
    core::FourSensorConfig g;
    g.N = 20;
    io::RawFourSensorScan layout;
    layout.geometry = g;
    for (int n = 0; n < g.positions(); ++n)
      layout.x_mm.push_back(n * g.dx_mm);
    ctx.begin(layout);
    while (!ctx.abort_requested())
      std::this_thread::sleep_for(1ms);
    return {acq::ScanOutcome::aborted, "aborted"};
  }
  void stop_motion() noexcept override {}
  std::string describe() const override { return "waiting backend"; }
};

// Short time-outs keep the test to a few seconds; long enough that the load is still in place
// when the legitimate client comes (it is timed from the moment the load is in place).
drivers::ModbusTcpServerOptions loaded_options() {
  drivers::ModbusTcpServerOptions o;
  o.port = 0;
  o.idle_timeout_ms = 3000;
  o.frame_timeout_ms = 3000;
  return o;
}

}  // namespace

TEST_CASE("server options: each bound is checked and named") {
  drivers::ModbusTcpServerOptions o;
  std::string why;
  CHECK(o.is_valid(&why));
  o.max_connections = 0;
  CHECK_FALSE(o.is_valid(&why));
  CHECK(why.find("max_connections = 0") != std::string::npos);
  o = {};
  o.frame_timeout_ms = 0;
  CHECK_FALSE(o.is_valid(&why));
  CHECK(why.find("frame_timeout_ms") != std::string::npos);
  o = {};
  o.idle_timeout_ms = -1;
  CHECK_FALSE(o.is_valid(&why));
  CHECK(why.find("idle_timeout_ms") != std::string::npos);
  CHECK_THROWS_AS(drivers::ModbusTcpServer("test", o, {}), std::invalid_argument);
}

TEST_CASE("register map: 200 idle and 20 half-open clients do not keep the start coil from a PLC") {
  test::TempDir tmp;
  acq::DaemonOptions opts;
  opts.results.dir = tmp / "r";
  opts.results.min_free_bytes = 0;
  opts.check_interval = 50ms;
  opts.stop_timeout = 500ms;
  const acq::SdNotifier quiet("", 0us);
  acq::Daemon d(
      opts, [] { return std::make_unique<WaitingBackend>(); }, quiet);
  const auto so = loaded_options();
  drivers::DaemonRegisterServer server(d, so);
  const int port = server.listen();
  server.start();
  std::atomic<int> rc{-1};
  std::thread run([&] { rc = d.run(); });
  struct Join {
    acq::Daemon& d;
    std::thread& t;
    ~Join() {
      d.request_stop();
      t.join();
    }
  } join{d, run};
  REQUIRE(eventually([&] { return d.status().state == acq::DaemonState::idle; }, 10s));

  Load load;
  REQUIRE(load.open(port) == kIdle + kHalfOpen);
  REQUIRE(eventually([&] { return server.stats().accepted >= kIdle + kHalfOpen; }, 5s));

  const auto t0 = clk::now();
  std::string out;
  const int status = test::mbpoll_write_coil(port, 0, 1, &out);
  const double ms = ms_since(t0);
  INFO("mbpoll: " << out);
  CHECK(status == 0);
  CHECK(ms < 1000.0);
  REQUIRE(eventually([&] { return d.status().state == acq::DaemonState::scanning; }, 2s));
  CHECK(d.status().last_trigger == acq::TriggerReply::accepted);
  CHECK(d.status().last_trigger_source == acq::TriggerSource::modbus);
  auto st = server.stats();
  print("register map", ms, st);
  // The half-open clients were still connected while the legitimate one was served.
  CHECK(st.frame_timeouts == 0);
  CHECK(st.evictions >= static_cast<std::uint64_t>(kIdle + kHalfOpen + 1 - so.max_connections));
  CHECK(st.connections <= so.max_connections);
  check_accounted(st);

  // Left alone, the half-open ones go at the frame time-out, the idle ones at the idle one.
  CHECK(eventually(
      [&] {
        const auto s = server.stats();
        return s.frame_timeouts == kHalfOpen && s.connections == 0;
      },
      6s));
  st = server.stats();
  print("register map, after the time-outs", ms, st);
  CHECK(st.idle_timeouts > 0);
  check_accounted(st);
}

TEST_CASE("device simulator: 200 idle and 20 half-open clients do not keep a read from a scan") {
  auto cfg = io::load_machine_config(test::source_dir() / "config" / "simulator.toml");
  cfg.simulator.port = 0;
  const auto so = loaded_options();
  drivers::ModbusDeviceSimulator sim(cfg, so);
  const int port = sim.listen();
  std::thread run([&] { sim.run(); });
  struct Join {
    drivers::ModbusDeviceSimulator& s;
    std::thread& t;
    ~Join() {
      s.request_stop();
      t.join();
    }
  } join{sim, run};

  Load load;
  REQUIRE(load.open(port) == kIdle + kHalfOpen);
  REQUIRE(eventually([&] { return sim.stats().accepted >= kIdle + kHalfOpen; }, 5s));

  const auto t0 = clk::now();
  const std::vector<long> regs = test::devsim_inputs(port, 0, 2);  // sensor 1, float32
  const double ms = ms_since(t0);
  CHECK(regs.size() == 2);
  CHECK(ms < 1000.0);
  const auto st = sim.stats();
  std::fprintf(stderr,
               "device simulator: read in %.0f ms under load; accepted %llu, evictions %llu, "
               "frame time-outs %llu, open %d\n",
               ms, static_cast<unsigned long long>(st.accepted),
               static_cast<unsigned long long>(st.evictions),
               static_cast<unsigned long long>(st.frame_timeouts), st.clients);
  // Counted just after the reply is sent: the client may have it first.
  CHECK(eventually([&] { return sim.stats().replies >= 1; }, 1s));
  CHECK(st.frame_timeouts == 0);
  CHECK(st.evictions >= static_cast<std::uint64_t>(kIdle + kHalfOpen + 1 - so.max_connections));
  CHECK(st.clients <= so.max_connections);
}

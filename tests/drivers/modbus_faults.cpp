// errsep's Modbus drivers against the device simulator (a real libmodbus TCP server on
// 127.0.0.1, ephemeral port): normal operation, then each fault the issue names.  In every case
// the drivers must say what happened (status of the read, counters) and never hand out a value
// that was not read.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <memory>
#include <thread>
#include <vector>

#include "errsep/core/four_sensor_model.hpp"
#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/drivers/device_factory.hpp"
#include "errsep/drivers/modbus_device_simulator.hpp"
#include "errsep/io/machine_config.hpp"
#include "support/support.hpp"

using namespace errsep;
using acq::IoStatus;
using namespace std::chrono_literals;

namespace {

/// The simulator of config/simulator.toml (noise off) serving from a thread of this test.
struct SimServer {
  io::MachineConfig cfg;
  std::unique_ptr<drivers::ModbusDeviceSimulator> sim;
  std::thread thread;

  explicit SimServer(const std::function<void(io::MachineConfig&)>& edit = {}) {
    cfg = io::load_machine_config(test::source_dir() / "config" / "simulator.toml");
    cfg.simulator.noise_sigma_um = 0.0;
    for (auto& b : cfg.buses) {  // short timeouts keep the fault tests fast
      b.response_timeout_ms = 40;
      b.retries = 1;
    }
    if (edit) edit(cfg);
    sim = std::make_unique<drivers::ModbusDeviceSimulator>(cfg);
    const int port = sim->listen();
    REQUIRE(port > 0);
    io::apply_simulator_port(cfg, port);
    thread = std::thread([this] { sim->run(); });
  }
  ~SimServer() {
    sim->request_stop();
    thread.join();
  }
};

drivers::Devices configured_devices(const io::MachineConfig& cfg) {
  drivers::SupervisorOptions so;
  so.poll = 5ms;
  so.initial_backoff = 20ms;
  so.max_backoff = 200ms;
  drivers::Devices d = drivers::make_devices(cfg, so);
  d.configure();
  return d;
}

// Every read is accounted for under exactly one outcome.
void check_accounted(const drivers::SensorCounters& c) {
  CHECK(c.reads ==
        c.ok + c.timeouts + c.disconnected + c.exceptions + c.out_of_range + c.not_configured);
}

template <typename F>
bool eventually(F&& f, std::chrono::milliseconds limit) {
  const auto end = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < end) {
    if (f()) return true;
    std::this_thread::sleep_for(5ms);
  }
  return f();
}

}  // namespace

TEST_CASE("sensor readings follow Eq. (1) of Zhao 2019 at the commanded positions") {
  SimServer srv;
  auto dev = configured_devices(srv.cfg);
  auto* slide = dev.stage("slide");
  auto* ustage = dev.stage("sensor_stage");
  auto* sensor = dev.sensor("sensor1");
  REQUIRE(slide);
  REQUIRE(ustage);
  REQUIRE(sensor);

  const auto t0 = std::chrono::steady_clock::now();
  REQUIRE(slide->move_to(50.0) == IoStatus::ok);   // 50 mm at 200 mm/s: 0.25 s + 5 ms settling
  REQUIRE(ustage->move_to(10.0) == IoStatus::ok);  // configuration 3: O = D2 + D3 = 10 mm
  REQUIRE(slide->wait_in_position(3000ms) == IoStatus::ok);
  REQUIRE(ustage->wait_in_position(3000ms) == IoStatus::ok);
  const double elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  CHECK(elapsed_s >= 0.25);  // finite speed: not there at once
  double x = 0;
  REQUIRE(slide->position(x) == IoStatus::ok);
  CHECK(x == Approx(50.0).margin(1e-4));

  acq::Sample s;
  REQUIRE(sensor->read(s) == IoStatus::ok);
  const core::SlidewayTruth truth = core::zhao2019_example1(srv.cfg.scan.geometry);
  const double expect = core::four_sensor_reading_um(truth, 50.0, 10.0) + srv.cfg.simulator.e_um[2];
  CHECK(s.value == Approx(expect).margin(1e-3));  // float32 register
  CHECK(s.t_ns > 0);
  CHECK(s.status == IoStatus::ok);

  // probe1..4 are "unused" by the single-sensor scan: they read 0 exactly (noise off).
  for (const char* name : {"probe1", "probe2", "probe3", "probe4"}) {
    acq::Sample p;
    REQUIRE(dev.sensor(name)->read(p) == IoStatus::ok);
    CHECK(p.value == Approx(0.0).margin(0.05));
  }
  check_accounted(sensor->counters());
}

TEST_CASE("four fixed sensors read their own configuration, in every data type") {
  SimServer srv([](io::MachineConfig& c) {
    c.scan.single_sensor = false;
    c.scan.sensors = {"probe1", "probe2", "probe3", "probe4"};
  });
  auto dev = configured_devices(srv.cfg);
  REQUIRE(dev.stage("slide")->move_to(30.0) == IoStatus::ok);
  REQUIRE(dev.stage("slide")->wait_in_position(3000ms) == IoStatus::ok);
  const core::SlidewayTruth truth = core::zhao2019_example1(srv.cfg.scan.geometry);
  const auto off = srv.cfg.scan.geometry.offsets_samples();
  const double quantum[4] = {0.001, 0.1, 0.05, 1e-4};  // int32 nm, int16 0.1 µm, uint16, float
  for (int i = 0; i < 4; ++i) {
    const std::string name = "probe" + std::to_string(i + 1);
    acq::Sample p;
    REQUIRE(dev.sensor(name)->read(p) == IoStatus::ok);
    const double expect = core::four_sensor_reading_um(truth, 30.0, off[i] * 5.0) +
                          srv.cfg.simulator.e_um[static_cast<std::size_t>(i)];
    INFO(name);
    CHECK(p.value == Approx(expect).margin(quantum[i]));
  }
}

TEST_CASE("server stops answering: timeout after retry, clear status, then the stage is stopped") {
  SimServer srv;
  auto dev = configured_devices(srv.cfg);
  auto* slide = dev.stage("slide");
  auto* sensor = dev.sensor("sensor1");
  auto* sbus = dev.bus("sensors");
  REQUIRE(slide->move_to(300.0) == IoStatus::ok);  // 1.5 s of travel
  acq::Sample s;
  REQUIRE(sensor->read(s) == IoStatus::ok);

  io::SimulatorFaults hang;
  hang.hang_after_requests = 1;  // the next request is not answered ...
  hang.hang_ms = 1000;           // ... nor any other for 1 s (both attempts fall in it)
  srv.sim->inject(hang);
  const auto before = sbus->counters();
  const auto t0 = std::chrono::steady_clock::now();
  const IoStatus st = sensor->read(s);
  const double took_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  CHECK(st == IoStatus::timeout);
  CHECK(s.status == IoStatus::timeout);
  CHECK(std::isnan(s.value));  // no stale value handed out
  const auto after = sbus->counters();
  CHECK(after.retries - before.retries == 1);  // retries = 1 in this config
  CHECK(after.timeouts - before.timeouts == 1);
  CHECK(after.requests - before.requests == 2);
  // Bounded: (1 + retries) × 40 ms plus scheduling slack (room for a loaded CI machine under
  // ASan; both attempts must fall in the 1 s hang); far below libmodbus's link recovery.
  CHECK(took_ms >= 70.0);
  CHECK(took_ms < 600.0);

  // The scan runner's reaction: stop the stage.  While the server hangs the stop cannot get
  // through; it is repeated until it does, and then the stage stays where it stopped.
  IoStatus stop_st = IoStatus::timeout;
  const bool stopped = eventually(
      [&] {
        stop_st = slide->stop();
        return stop_st == IoStatus::ok;
      },
      3000ms);
  REQUIRE(stopped);
  double p1 = 0, p2 = 0;
  REQUIRE(slide->position(p1) == IoStatus::ok);
  std::this_thread::sleep_for(100ms);
  REQUIRE(slide->position(p2) == IoStatus::ok);
  CHECK(p1 == p2);                                            // not moving any more
  CHECK(p1 < 300.0);                                          // stopped short of the target
  CHECK(slide->wait_in_position(50ms) == IoStatus::timeout);  // not "in position"
  CHECK(srv.sim->stats().ignored >= 2);
  // After the hang the sensor answers again.
  CHECK(eventually([&] { return sensor->read(s) == IoStatus::ok; }, 2000ms));
  check_accounted(sensor->counters());
}

TEST_CASE("connection drop: disconnected status, supervisor reconnects, reads resume") {
  SimServer srv;
  auto dev = configured_devices(srv.cfg);
  auto* sensor = dev.sensor("sensor1");
  auto* sbus = dev.bus("sensors");
  acq::Sample s;
  REQUIRE(sensor->read(s) == IoStatus::ok);

  io::SimulatorFaults drop;
  drop.drop_after_requests = 1;
  srv.sim->inject(drop);
  const IoStatus st = sensor->read(s);
  CHECK(st == IoStatus::disconnected);
  CHECK(std::isnan(s.value));
  CHECK(sbus->counters().disconnects == 1);
  CHECK(srv.sim->stats().drops == 1);

  // Reads while the link is down return at once with `disconnected`; the supervisor reconnects.
  int ok_reads = 0, down_reads = 0, other = 0;
  const bool back = eventually(
      [&] {
        const IoStatus r = sensor->read(s);
        (r == IoStatus::ok ? ok_reads : r == IoStatus::disconnected ? down_reads : other)++;
        return r == IoStatus::ok;
      },
      3000ms);
  CHECK(back);
  CHECK(other == 0);
  CHECK(ok_reads == 1);
  CHECK(sbus->counters().reconnects >= 1);
  // The motion bus lost its connection too (the server dropped every client): its next
  // request says so, and after the reconnect the stage answers again.
  auto* slide = dev.stage("slide");
  double pos = 0;
  CHECK(eventually([&] { return slide->position(pos) == IoStatus::ok; }, 3000ms));
  CHECK(dev.bus("motion")->counters().reconnects >= 1);
  check_accounted(sensor->counters());
  const auto c = sensor->counters();
  CHECK(c.disconnected == static_cast<std::uint64_t>(down_reads) + 1);
}

TEST_CASE("Modbus exception response: device_exception with its code, no reconnect") {
  SimServer srv;
  auto dev = configured_devices(srv.cfg);
  auto* sensor = dev.sensor("sensor1");
  auto* sbus = dev.bus("sensors");
  io::SimulatorFaults ex;
  ex.exception_after_requests = 1;
  ex.exception_count = 2;
  ex.exception_code = 4;  // server device failure
  srv.sim->inject(ex);
  acq::Sample s;
  CHECK(sensor->read(s) == IoStatus::device_exception);
  CHECK(std::isnan(s.value));
  CHECK(sensor->read(s) == IoStatus::device_exception);
  CHECK(sensor->read(s) == IoStatus::ok);
  const auto c = sbus->counters();
  CHECK(c.exceptions == 2);
  CHECK(c.last_exception_code == 4);
  CHECK(c.retries == 0);  // an answer is an answer: no retry
  CHECK(c.disconnects == 0);
  CHECK(sensor->counters().exceptions == 2);
  check_accounted(sensor->counters());

  // A register the device does not have: configure() names the sensor and the register.
  io::SensorConfig wrong = *srv.cfg.find_sensor("sensor1");
  wrong.name = "wrong";
  wrong.reg.address = 900;
  drivers::ModbusSensor bad(wrong, *sbus, 9);
  try {
    bad.configure();
    FAIL("configure() accepted a register the device does not serve");
  } catch (const std::runtime_error& e) {
    const std::string m = e.what();
    CHECK(m.find("sensor 'wrong'") != std::string::npos);
    CHECK(m.find("Modbus exception 2") != std::string::npos);  // illegal data address
    CHECK(m.find("input register 900") != std::string::npos);
  }
}

TEST_CASE("out-of-range reading is flagged, with the value kept for the record") {
  SimServer srv;
  auto dev = configured_devices(srv.cfg);
  auto* sensor = dev.sensor("sensor1");
  io::SimulatorFaults oor;
  oor.out_of_range_sensor = "sensor1";
  srv.sim->inject(oor);
  acq::Sample s;
  CHECK(sensor->read(s) == IoStatus::out_of_range);
  CHECK(s.status == IoStatus::out_of_range);
  CHECK(s.value > sensor->config().range_max_um);
  srv.sim->inject({});
  CHECK(sensor->read(s) == IoStatus::ok);
  CHECK(sensor->counters().out_of_range == 1);
  check_accounted(sensor->counters());
}

TEST_CASE("a drive fault ends wait_in_position with fault and its fault code") {
  SimServer srv;
  auto dev = configured_devices(srv.cfg);
  auto* slide = dev.stage("slide");
  REQUIRE(slide->move_to(100.0) == IoStatus::ok);
  std::this_thread::sleep_for(50ms);
  REQUIRE(srv.sim->set_stage_fault("slide", true, 0x21));
  CHECK(slide->wait_in_position(2000ms) == IoStatus::fault);
  unsigned code = 0;
  REQUIRE(slide->fault_code(code) == IoStatus::ok);
  CHECK(code == 0x21);
  double p = 0;
  REQUIRE(slide->position(p) == IoStatus::ok);
  CHECK(p < 100.0);
}

TEST_CASE("errsep-devsim prints its port, serves, applies command-line faults, stops on SIGTERM") {
  const auto app = test::app_path("devsim");
  if (!std::filesystem::exists(app)) {
    WARN("SKIPPED: " << app << " is not built");
    return;
  }
  int out[2];
  REQUIRE(pipe(out) == 0);
  const std::string config = (test::source_dir() / "config" / "simulator.toml").string();
  const pid_t pid = fork();
  REQUIRE(pid >= 0);
  if (pid == 0) {
    dup2(out[1], 1);
    close(out[0]);
    close(out[1]);
    execl(app.c_str(), app.c_str(), "--config", config.c_str(), "--port", "0", "--exception-after",
          "2", "--exception-code", "6", nullptr);
    _exit(127);
  }
  close(out[1]);
  FILE* f = fdopen(out[0], "r");
  char line[128] = {};
  const bool got = std::fgets(line, sizeof line, f) != nullptr;
  int port = 0;
  const bool parsed = got && std::sscanf(line, "listening 127.0.0.1:%d", &port) == 1;
  if (parsed) {
    io::MachineConfig cfg = io::load_machine_config(config);
    io::apply_simulator_port(cfg, port);
    drivers::ModbusBus bus(cfg.buses[0]);
    bus.configure();
    drivers::ModbusSensor sensor(*cfg.find_sensor("sensor1"), bus, 0);
    sensor.configure();  // request 1
    acq::Sample s;
    CHECK(sensor.read(s) == IoStatus::device_exception);  // request 2: --exception-after 2
    CHECK(bus.counters().last_exception_code == 6);
    CHECK(sensor.read(s) == IoStatus::ok);  // --exception-count defaults to 1
  }
  kill(pid, SIGTERM);
  int status = 0;
  bool exited = false;
  for (int i = 0; i < 200 && !exited; ++i) {
    exited = waitpid(pid, &status, WNOHANG) == pid;
    if (!exited) std::this_thread::sleep_for(10ms);
  }
  if (!exited) {
    kill(pid, SIGKILL);
    waitpid(pid, &status, 0);
  }
  std::fclose(f);
  INFO("first line: " << line);
  REQUIRE(parsed);
  CHECK(port > 0);
  CHECK(exited);  // within 2 s of SIGTERM
  CHECK(WIFEXITED(status));
  CHECK(WEXITSTATUS(status) == 0);
}

TEST_CASE("displacement method: the reference sensor sees r(x + d) + m(x) after displacing d") {
  SimServer srv;
  auto dev = configured_devices(srv.cfg);
  auto* slide = dev.stage("slide");
  auto* piece = dev.stage("reference_piece");
  auto* ws = dev.sensor("workpiece");
  auto* rs = dev.sensor("reference");
  const auto& sim = srv.cfg.simulator;
  REQUIRE(slide->move_to(20.0) == IoStatus::ok);
  REQUIRE(slide->wait_in_position(3000ms) == IoStatus::ok);
  acq::Sample w, r1, r2;
  REQUIRE(ws->read(w) == IoStatus::ok);
  REQUIRE(rs->read(r1) == IoStatus::ok);
  CHECK(w.value == Approx(sim.w_um.eval(20.0) + sim.m_um.eval(20.0)).margin(1e-4));
  CHECK(r1.value == Approx(sim.r_um.eval(20.0) + sim.m_um.eval(20.0)).margin(1e-3));  // int32 nm
  const double d = srv.cfg.scan.d_mm;
  REQUIRE(piece->move_to(d) == IoStatus::ok);
  REQUIRE(piece->wait_in_position(3000ms) == IoStatus::ok);
  REQUIRE(rs->read(r2) == IoStatus::ok);
  // Haramiishi 2024 Eq. (3): S2_2(x) = r(x + d) + m(x).
  CHECK(r2.value == Approx(sim.r_um.eval(20.0 + d) + sim.m_um.eval(20.0)).margin(1e-3));
  CHECK(std::abs(r2.value - r1.value) > 0.01);  // the displacement is visible
}

TEST_CASE("noise has the configured sigma and drift grows linearly in time") {
  SimServer srv([](io::MachineConfig& c) {
    c.simulator.noise_sigma_um = 0.5;
    c.simulator.drift_um_per_s = 20.0;
  });
  auto dev = configured_devices(srv.cfg);
  auto* s = dev.sensor("sensor1");
  // Mean and spread of 400 readings at a standstill; the drift over the ~0.1 s this takes is
  // removed by a linear fit against the sample times.
  const int n = 400;
  std::vector<double> t(n), v(n);
  for (int i = 0; i < n; ++i) {
    acq::Sample x;
    REQUIRE(s->read(x) == IoStatus::ok);
    t[static_cast<std::size_t>(i)] = x.t_ns * 1e-9;
    v[static_cast<std::size_t>(i)] = x.value;
  }
  double tm = 0, vm = 0;
  for (int i = 0; i < n; ++i) {
    tm += t[static_cast<std::size_t>(i)] / n;
    vm += v[static_cast<std::size_t>(i)] / n;
  }
  double stt = 0, stv = 0;
  for (int i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    stt += (t[k] - tm) * (t[k] - tm);
    stv += (t[k] - tm) * (v[k] - vm);
  }
  const double slope = stv / stt;
  double ss = 0;
  for (int i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const double e = v[k] - vm - slope * (t[k] - tm);
    ss += e * e;
  }
  const double sigma = std::sqrt(ss / (n - 2));
  CHECK(sigma == Approx(0.5).epsilon(0.15));  // 400 samples: relative s.e. of σ ≈ 3.5 %
  // Drift: two readings 300 ms apart differ by about 6 µm (noise 0.5 µm each).
  acq::Sample a, b;
  REQUIRE(s->read(a) == IoStatus::ok);
  std::this_thread::sleep_for(300ms);
  REQUIRE(s->read(b) == IoStatus::ok);
  const double dt = (b.t_ns - a.t_ns) * 1e-9;
  CHECK((b.value - a.value) == Approx(20.0 * dt).margin(2.5));
}

TEST_CASE("a bus that cannot be opened says which bus, where, and what to check") {
  io::BusConfig tcp;
  tcp.name = "drive";
  tcp.kind = io::BusKind::tcp;
  tcp.host = "127.0.0.1";
  tcp.port = 1;  // nothing listens on port 1
  tcp.response_timeout_ms = 200;
  drivers::ModbusBus b1(tcp);
  try {
    b1.configure();
    FAIL("connected to port 1");
  } catch (const std::runtime_error& e) {
    const std::string m = e.what();
    CHECK(m.find("bus 'drive' (tcp 127.0.0.1:1): cannot connect") == 0);
  }
  acq::Sample s;
  io::SensorConfig sc;
  sc.name = "s";
  drivers::ModbusSensor sensor(sc, b1, 0);
  CHECK(sensor.read(s) == IoStatus::not_configured);  // never a value from an unopened bus

  io::BusConfig rtu;
  rtu.name = "rs485";
  rtu.kind = io::BusKind::rtu;
  rtu.device = "/dev/errsep-no-such-tty";
  rtu.parity = io::Parity::even;
  drivers::ModbusBus b2(rtu);
  try {
    b2.configure();
    FAIL("opened a device that does not exist");
  } catch (const std::runtime_error& e) {
    const std::string m = e.what();
    CHECK(m.find("bus 'rs485' (rtu /dev/errsep-no-such-tty 115200 8E1): cannot connect") == 0);
    CHECK(m.find("check the device path") != std::string::npos);
  }
}

// errsep-devsim: the device simulator (a Modbus TCP server on loopback playing the machine of a
// machine config).  Prints "listening <host>:<port>" on stdout once it accepts connections, and
// stops cleanly on SIGINT/SIGTERM.  --compensation TABLE: the simulated controller applies a
// compensation table (measure - compensate - verify).
#include <CLI/CLI.hpp>
#include <csignal>
#include <cstdio>
#include <exception>
#include <iostream>

#include "errsep/drivers/modbus_device_simulator.hpp"
#include "errsep/io/machine_config.hpp"
#include "errsep/version.hpp"

namespace {
errsep::drivers::ModbusDeviceSimulator* g_sim = nullptr;
extern "C" void on_signal(int) {
  if (g_sim) g_sim->request_stop();  // one atomic store: async-signal-safe
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "errsep device simulator: a Modbus TCP server on 127.0.0.1 playing the sensors, "
      "stages and reference pieces of a machine config"};
  app.set_version_flag("--version", std::string(errsep::kVersion));
  std::string config_path;
  int port = -1;
  std::string host;
  errsep::io::SimulatorFaults f;
  bool f_set[7] = {};
  app.add_option("-c,--config", config_path, "machine config (TOML), e.g. config/simulator.toml")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("-p,--port", port, "TCP port (0 = ephemeral); default: [simulator] port")
      ->check(CLI::Range(0, 65535));
  app.add_option("--host", host, "127.0.0.1 or ::1; default: [simulator] host")
      ->check(CLI::IsMember({"127.0.0.1", "::1"}));
  app.add_option("--hang-after", f.hang_after_requests,
                 "fault: stop answering after this many requests")
      ->each([&](const std::string&) { f_set[0] = true; });
  app.add_option("--hang-ms", f.hang_ms, "fault: ... for this long (0 = forever)")
      ->each([&](const std::string&) { f_set[1] = true; });
  app.add_option("--drop-after", f.drop_after_requests,
                 "fault: close every connection once after this many requests")
      ->each([&](const std::string&) { f_set[2] = true; });
  app.add_option("--exception-after", f.exception_after_requests,
                 "fault: answer with a Modbus exception after this many requests")
      ->each([&](const std::string&) { f_set[3] = true; });
  app.add_option("--exception-count", f.exception_count, "fault: ... for this many requests")
      ->each([&](const std::string&) { f_set[4] = true; });
  app.add_option("--exception-code", f.exception_code, "fault: the exception code (1..11)")
      ->check(CLI::Range(1, 11))
      ->each([&](const std::string&) { f_set[5] = true; });
  std::string compensation;
  app.add_option("--compensation", compensation,
                 "a compensation table (any errsep format: .ini, .hal, .lis, .COM, .csv) the "
                 "simulated controller applies to the output axis at the slide's machine position")
      ->check(CLI::ExistingFile);
  app.add_option("--out-of-range", f.out_of_range_sensor,
                 "fault: this sensor reads range_max_um + 1000 µm")
      ->each([&](const std::string&) { f_set[6] = true; });
  CLI11_PARSE(app, argc, argv);

  try {
    errsep::io::MachineConfig cfg = errsep::io::load_machine_config(config_path);
    if (port >= 0) cfg.simulator.port = port;
    if (!compensation.empty()) cfg.simulator.compensation_table = compensation;
    if (!host.empty()) cfg.simulator.host = host;
    auto& cf = cfg.simulator.faults;
    if (f_set[0]) cf.hang_after_requests = f.hang_after_requests;
    if (f_set[1]) cf.hang_ms = f.hang_ms;
    if (f_set[2]) cf.drop_after_requests = f.drop_after_requests;
    if (f_set[3]) cf.exception_after_requests = f.exception_after_requests;
    if (f_set[4]) cf.exception_count = f.exception_count;
    if (f_set[5]) cf.exception_code = f.exception_code;
    if (f_set[6]) {
      if (!cfg.find_sensor(f.out_of_range_sensor))
        throw std::runtime_error("--out-of-range: no [[sensor]] named '" + f.out_of_range_sensor +
                                 "' in " + config_path);
      cf.out_of_range_sensor = f.out_of_range_sensor;
    }

    errsep::drivers::ModbusDeviceSimulator sim(cfg);
    const int actual = sim.listen();
    g_sim = &sim;
    struct sigaction sa {};
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, nullptr);
    sigaction(SIGTERM, &sa, nullptr);
    const bool v6 = sim.host().find(':') != std::string::npos;
    std::printf("listening %s%s%s:%d\n", v6 ? "[" : "", sim.host().c_str(), v6 ? "]" : "", actual);
    std::fflush(stdout);
    sim.run();
    g_sim = nullptr;
    const auto s = sim.stats();
    std::fprintf(
        stderr,
        "errsep-devsim: stopped; %llu requests, %llu replies, %llu exceptions sent, "
        "%llu left unanswered, %llu drops, %llu connections\n",
        static_cast<unsigned long long>(s.requests), static_cast<unsigned long long>(s.replies),
        static_cast<unsigned long long>(s.exceptions_sent),
        static_cast<unsigned long long>(s.ignored), static_cast<unsigned long long>(s.drops),
        static_cast<unsigned long long>(s.accepted));
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "errsep-devsim: %s\n", e.what());
    return 1;
  }
}

#pragma once
// The device simulator: a Modbus TCP server (libmodbus) on loopback that plays the machine
// described by a machine config, so that a scan without a machine runs the same code as on one.
//
// It serves every [[sensor]] and [[stage]] of the config at the registers the config gives
// (one address space for all unit ids, as a TCP gateway with one device would; overlapping
// registers are refused at start), and plays:
//  - stages moving at finite speed (simulator.stage_speed_mm_s, or the speed register when
//    written) toward the last target written; the in-position bit is set settle_ms after
//    arrival; writing 1 to the stop coil stops the stage where it is (in-position stays clear);
//  - the four-sensor model of Zhao 2019 Eq. (1): the scan's sensor reads
//    f(x + O) + S(x) + O·γ(x) + e_i, with x the slide position − scan.slide_start_mm and O the
//    sensor offset: the sensor-stage position − scan.sensor_stage_origin_mm (single sensor; e_i of
//    the nearest configuration) or the fixed offset of configuration i (four sensors);
//  - the displacement method of Haramiishi 2024 section 2.1: the workpiece sensor reads
//    w(x) + m(x), the reference sensor r(x + p) + m(x) with p the reference-piece stage position;
//  - a compensation table (simulator.compensation_table, any errsep format): the simulated
//    controller adds c(p) to the output axis at the slide's machine position p, so the scan's
//    sensors read reading_sign * c(p) more (measure - compensate - verify);
//  - machine coordinates: the truth S, gamma, f is laid over the scan, x = (slide position -
//    scan.slide_start_mm) * axes.scan_direction;
//  - Gaussian noise σ and a linear drift in time on every reading; sensors the scan does not use
//    read 0 (+ noise + drift).
// Fault injection (config [simulator.faults], the command line, or inject() at run time): stop
// answering, drop every connection, answer with a Modbus exception, an out-of-range reading.
// Several clients are served at once by the shared Modbus TCP server loop
// (drivers/modbus_tcp_server.hpp): idle and half-open connections time out, the oldest idle one
// is evicted at the connection cap.
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "errsep/drivers/modbus_tcp_server.hpp"
#include "errsep/io/machine_config.hpp"

namespace errsep::drivers {

struct SimulatorStats {
  std::uint64_t requests = 0;         ///< requests received
  std::uint64_t replies = 0;          ///< normal replies sent
  std::uint64_t exceptions_sent = 0;  ///< exception replies sent by fault injection
  std::uint64_t ignored = 0;          ///< requests left unanswered (hang)
  std::uint64_t drops = 0;            ///< times all connections were dropped
  std::uint64_t accepted = 0;         ///< client connections accepted
  std::uint64_t evictions = 0;        ///< idle connections closed to admit a new one at the cap
  std::uint64_t idle_timeouts = 0;    ///< connections closed for idleness
  std::uint64_t frame_timeouts = 0;   ///< connections closed with a partial request (half-open)
  int clients = 0;                    ///< clients connected now
};

class ModbusDeviceSimulator {
 public:
  /// Builds the simulated machine from cfg (cfg.simulator: truth, noise, faults, host, port,
  /// compensation table).  Throws std::runtime_error when the config cannot be served
  /// (overlapping registers, a host that is not loopback, a table that cannot be read or
  /// compensates other axes than the scan measures).
  /// `server`: connection cap and time-outs of its Modbus TCP server (its host and port are
  /// taken from cfg.simulator).
  explicit ModbusDeviceSimulator(const io::MachineConfig& cfg, ModbusTcpServerOptions server = {});
  ~ModbusDeviceSimulator();
  ModbusDeviceSimulator(const ModbusDeviceSimulator&) = delete;
  ModbusDeviceSimulator& operator=(const ModbusDeviceSimulator&) = delete;

  /// Binds and listens on cfg.simulator.host:port (port 0 = ephemeral).  Returns the actual
  /// port.  Throws std::runtime_error naming the address.
  int listen();
  int port() const noexcept { return port_; }
  const std::string& host() const noexcept;

  /// Serves clients until request_stop().  Call after listen(), from one thread.
  void run();
  /// Thread-safe and async-signal-safe (one atomic store): run() returns within ~10 ms.
  void request_stop() noexcept { stop_.store(true, std::memory_order_relaxed); }

  /// Replaces the fault schedule at run time; request counts restart from now ("after N more
  /// requests").  Thread-safe.
  void inject(const io::SimulatorFaults& faults);
  /// Sets or clears the fault bit of a stage (a drive fault).  Thread-safe.  False if unknown.
  bool set_stage_fault(const std::string& stage, bool fault, unsigned code = 0x21);

  SimulatorStats stats() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  int port_ = 0;
  std::atomic<bool> stop_{false};
};

}  // namespace errsep::drivers

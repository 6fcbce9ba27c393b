#pragma once
// The daemon's own Modbus TCP register map, for the cell controller (libmodbus server, loopback
// by default).  Addresses are 0-based (mbpoll: add 1, or use -0).
//
// Coils (function 5 / 15; momentary, they read back 0):
//   0  start: writing 1 triggers a scan.  Refused triggers are answered with Modbus exception 6
//      (server device busy) and the reason code is in input register 1.
//   1  abort: writing 1 aborts the running scan (its raw data is kept, marked incomplete).
// Input registers (function 4):
//   0  state            DaemonState: 0 starting, 1 idle, 2 scanning, 3 fault, 4 stopping
//   1  last trigger     TriggerReply: 1 accepted, 2 refused (scan running), 3 refused (fault),
//                       4 refused (stopping), 5 refused (starting), 6 refused (scan pending)
//   2  scan id          of the running scan, low 16 bits (0 = none)
//   3  points done      of the running scan
//   4  points total
//   5  scans completed  since start, low 16 bits
//   6  last scan id     low 16 bits
//   7  last outcome     ScanOutcome: 1 complete, 2 aborted, 3 device fault, 4 stopped, 5 write
//                       failed
//   8,9 straightness    of the last result, nm, int32, high word first; INT32_MIN = none:
//                       ISO 230-1 straightness deviation of S(x) about the MINIMUM-ZONE
//                       reference line (result file key straightness_minimum_zone_um)
//   10 faults           times the fault state was entered, low 16 bits
//   11 alive            seconds since the server started, low 16 bits
//   12 map version      2
//   13 trigger source   of register 1: 0 modbus (start coil), 1 GPIO start input, 2 schedule,
//                       3 command (TriggerSource)
//   14,15 straightness  of the last result about the LEAST-SQUARES reference line, nm, int32 as
//                       8,9 (key straightness_least_squares_um)
//   16,17 U             expanded uncertainty (k = 2) of registers 8,9, nm, int32 as 8,9
//                       (key straightness_minimum_zone_U_um)
// Version 1 had registers 0..12, with 8,9 = max - min of S(x) (no reference line removed).
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>

#include "errsep/acq/daemon.hpp"
#include "errsep/drivers/modbus_tcp_server.hpp"

namespace errsep::drivers {

/// Address, connection cap and time-outs of the register map's server (loopback, port 1502 by
/// default).
using RegisterServerOptions = ModbusTcpServerOptions;

inline constexpr int kRegisterMapVersion = 2;
inline constexpr int kInputRegisterCount = 18;

class DaemonRegisterServer {
 public:
  /// `daemon` must outlive the server.
  DaemonRegisterServer(acq::Daemon& daemon, RegisterServerOptions opts);
  ~DaemonRegisterServer();  ///< stops the thread
  DaemonRegisterServer(const DaemonRegisterServer&) = delete;
  DaemonRegisterServer& operator=(const DaemonRegisterServer&) = delete;

  /// Binds and listens; returns the actual port.  Throws std::runtime_error naming the address.
  int listen();
  /// Serves on its own thread until stop().
  void start();
  void stop() noexcept;
  int port() const noexcept;
  /// Connections, evictions and time-outs of the server.  Thread-safe.
  ModbusTcpServerStats stats() const noexcept;

 private:
  ModbusConnectionAction handle(_modbus* ctx, const std::uint8_t* q, int length);
  struct Impl;
  std::unique_ptr<Impl> impl_;
  acq::Daemon& daemon_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace errsep::drivers

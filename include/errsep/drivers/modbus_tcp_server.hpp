#pragma once
// One Modbus TCP server loop (libmodbus builds the context, listens and answers with
// modbus_reply), shared by the daemon's register map and the device simulator.
//
// A misbehaving client must not lock the others out, so the loop never blocks on one client:
//  - every client socket is non-blocking; poll() watches the listening socket and every client;
//  - a request is gathered per connection from whatever bytes have arrived and cut by its MBAP
//    length (Modbus Messaging on TCP/IP, section 3.1.3: 7-byte header, length = unit id + PDU),
//    then handed to the handler whole.  libmodbus's modbus_receive() is not the reader: it waits
//    in select() for the rest of a frame (byte time-out, 500 ms by default, per call), so one
//    client sending half a frame would stall every other client;
//  - a frame begun and not finished within frame_timeout_ms (half-open: a partial request then
//    silence) closes that connection; so does no complete request for idle_timeout_ms;
//  - when max_connections are open, a new client is admitted by evicting the connection that has
//    gone longest without a complete request (the oldest idle one);
//  - a reply the client does not take (its window full) fails the non-blocking send and closes
//    that connection instead of blocking the loop.
// Not real-time: it allocates (per connection) and does I/O; it runs on its own thread.
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

struct _modbus;  // libmodbus's modbus_t; only drivers/*.cpp include <modbus.h>

namespace errsep::drivers {

struct ModbusTcpServerOptions {
  std::string host = "127.0.0.1";  ///< address to bind (loopback by default)
  int port = 1502;                 ///< 0 = ephemeral (see ModbusTcpServer::port())
  int max_connections = 32;        ///< beyond it the oldest idle connection is evicted
  /// No complete request for this long closes a connection (an abandoned HMI, a stuck scanner).
  /// A client polling every few seconds stays connected.
  int idle_timeout_ms = 60000;
  /// A request begun must be complete within this (≤ 260 bytes: on a LAN it arrives at once;
  /// libmodbus's own byte time-out is 500 ms).
  int frame_timeout_ms = 1000;
  int backlog = 256;  ///< listen() backlog: connections the kernel queues between two polls
  bool is_valid(std::string* why = nullptr) const;
};

struct ModbusTcpServerStats {
  std::uint64_t accepted = 0;        ///< connections admitted
  std::uint64_t requests = 0;        ///< complete requests handed to the handler
  std::uint64_t evictions = 0;       ///< idle connections closed to admit a new one at the cap
  std::uint64_t idle_timeouts = 0;   ///< closed after idle_timeout_ms without a request
  std::uint64_t frame_timeouts = 0;  ///< closed with a partial request older than frame_timeout_ms
  std::uint64_t malformed = 0;       ///< closed on a header that is not Modbus TCP
  std::uint64_t closed_by_peer = 0;  ///< the client closed or reset the connection
  std::uint64_t send_failures = 0;   ///< a reply could not be sent (closed)
  int connections = 0;               ///< open now
};

/// What the handler wants done with the connection after a request.
enum class ModbusConnectionAction { keep, close, close_all };

class ModbusTcpServer {
 public:
  /// Called on the serving thread with one complete request (MBAP header included, `length`
  /// bytes; the buffer holds MODBUS_TCP_MAX_ADU_LENGTH bytes, zero beyond the request).  `ctx`
  /// is set to the client's socket: answer with modbus_reply / modbus_reply_exception, whose
  /// failure (-1) should return close.
  using Handler =
      std::function<ModbusConnectionAction(_modbus* ctx, const std::uint8_t* request, int length)>;

  /// `what` names the server in error messages ("register map", "simulator").  Throws
  /// std::invalid_argument when opts is not valid.
  ModbusTcpServer(std::string what, ModbusTcpServerOptions opts, Handler handler);
  ~ModbusTcpServer();  ///< closes every socket and frees the libmodbus context
  ModbusTcpServer(const ModbusTcpServer&) = delete;
  ModbusTcpServer& operator=(const ModbusTcpServer&) = delete;

  /// Binds and listens; returns the actual port.  Throws std::runtime_error naming the address.
  int listen();
  int port() const noexcept { return port_; }
  const ModbusTcpServerOptions& options() const noexcept { return opts_; }

  /// Serves until `stop` becomes true (checked at least every 10 ms); call after listen(), from
  /// one thread.  Closes every client connection before it returns.
  void run(const std::atomic<bool>& stop);

  /// Thread-safe.
  ModbusTcpServerStats stats() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::string what_;
  ModbusTcpServerOptions opts_;
  Handler handler_;
  int port_ = 0;
};

}  // namespace errsep::drivers

#pragma once
// One connection to an MQTT broker through libmosquitto (Debian libmosquitto1): the only code
// that includes <mosquitto.h>.  Not thread-safe: one thread owns the client and runs its network
// loop (service/plant_publisher.hpp runs it on a thread of its own, never the sampling thread).
// Not real-time safe (sockets, TLS, allocation).
//
// Each connect() starts from a fresh libmosquitto instance (clean session): nothing the library
// kept of a dropped connection is re-sent behind the caller's back; the caller re-publishes
// whatever was not acknowledged (at least once, duplicates carry their scan id).
#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>

struct mosquitto;  // libmosquitto's handle (global namespace)

namespace errsep::drivers {

struct MqttClientOptions {
  std::string host = "127.0.0.1";
  int port = 1883;
  std::string client_id;
  std::string username, password;     ///< empty username: anonymous
  std::filesystem::path tls_ca_file;  ///< set: TLS, the broker's certificate verified against it
  std::filesystem::path tls_cert_file, tls_key_file;
  int keepalive_s = 30;
  std::string will_topic, will_payload;  ///< empty topic: no last will
  int will_qos = 1;
  bool will_retain = true;
  bool is_valid(std::string* why = nullptr) const;
};

class MqttClient {
 public:
  /// Throws std::invalid_argument for invalid options.
  explicit MqttClient(MqttClientOptions opts);
  ~MqttClient();
  MqttClient(const MqttClient&) = delete;
  MqttClient& operator=(const MqttClient&) = delete;

  /// Opens the connection (non-blocking TCP connect) and waits for the broker's CONNACK up to
  /// `timeout`, or until `*abort` becomes true.  False, with the reason in `why` (refused: not
  /// authorised, TLS handshake failed, no broker, no answer), when not connected.
  bool connect(std::chrono::milliseconds timeout, std::string* why,
               const std::atomic<bool>* abort = nullptr);
  bool connected() const noexcept { return connected_; }
  /// Queues a PUBLISH; returns its message id (> 0), or 0 with the reason in `why`.  For QoS >=
  /// 1, on_ack(mid) is called from loop() when the broker acknowledged it (PUBACK / PUBCOMP).
  int publish(const std::string& topic, const std::string& payload, int qos, bool retain,
              std::string* why);
  bool subscribe(const std::string& topic, int qos, std::string* why);
  /// Runs the network for up to `timeout` (reads, writes, keepalive); callbacks run here.  A lost
  /// connection makes connected() false (the reason in last_error()).
  void loop(std::chrono::milliseconds timeout);
  /// Clean DISCONNECT (the broker does not send the last will).
  void disconnect();
  const std::string& last_error() const noexcept { return last_error_; }

  std::function<void(int mid)> on_ack;
  std::function<void(const std::string& topic, const std::string& payload)> on_message;

 private:
  void destroy() noexcept;
  MqttClientOptions opts_;
  ::mosquitto* mosq_ = nullptr;
  bool connected_ = false;
  int connack_ = -1;  ///< -1: none yet
  std::string last_error_;
  friend struct MqttCallbacks;
};

}  // namespace errsep::drivers

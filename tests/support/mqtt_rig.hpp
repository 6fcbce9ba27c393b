#pragma once
// Test rig of the MQTT tests: a real Mosquitto broker (Debian `mosquitto`, not written here)
// started by the test on 127.0.0.1 with ephemeral ports, its own config, password file
// (mosquitto_passwd -b), ACL and, on request, a TLS listener with a CA made by openssl in the
// test; a subscriber (`mosquitto_sub`) writing every message it receives to a file; commands
// sent with `mosquitto_pub`; every payload checked against schema/mqtt-messages.schema.json by
// python3-jsonschema (/usr/bin/python3).  Nothing is started as a system service.
//
// Users of the password file (password "<user>-pw"): one per machine (the machine's name, as
// the plant ACL in README.md gives it), "plant" (may send commands, reads everything),
// "viewer" (reads everything, may send nothing).
#include <chrono>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "support/daemon_rig.hpp"
#include "support/support.hpp"

namespace errsep::test {

/// Why an MQTT test cannot run here ("" = it can): mosquitto, mosquitto_sub/_pub/_passwd,
/// openssl or python3-jsonschema missing.
std::string mqtt_tools_missing();

struct MqttBrokerOptions {
  std::vector<std::string> machines;  ///< a user per machine
  bool plain = true;                  ///< a plain-TCP listener (port)
  bool tls = false;                   ///< a TLS listener (tls_port), CA made here
  bool persistence = true;            ///< keep sessions and queued messages across restarts
};

class MqttBroker {
 public:
  explicit MqttBroker(MqttBrokerOptions opts);
  ~MqttBroker();
  /// Starts mosquitto (the same ports again after a stop); throws when it does not listen.
  void start();
  /// SIGTERM (a clean stop: the persistence file is written) and wait.
  void stop();
  void signal(int sig);
  int port() const { return port_; }
  int tls_port() const { return tls_port_; }
  std::filesystem::path ca_file() const { return dir_ / "ca.crt"; }
  /// A file holding "<user>-pw" (for a machine config's password_file).
  std::filesystem::path password_file(const std::string& user) const;
  std::string log() const;
  const std::filesystem::path& dir() const { return dir_.path(); }

 private:
  MqttBrokerOptions opts_;
  TempDir dir_;
  int port_ = 0, tls_port_ = 0;
  std::unique_ptr<Child> proc_;
};

struct MqttMessage {
  std::string topic;
  bool retained = false;
  std::string payload;
};

/// mosquitto_sub as `user` on `topic` (QoS 1); with `session` a persistent session of that
/// client id (messages queued for it while it is away, e.g. across a broker restart).
class MqttSubscriber {
 public:
  MqttSubscriber(const MqttBroker& broker, const std::string& user, const std::string& topic,
                 const std::string& session = {});
  ~MqttSubscriber();
  /// Every message received so far.
  std::vector<MqttMessage> messages() const;
  /// Waits until pred(messages()) or the timeout; returns the last messages.
  template <class Pred>
  std::vector<MqttMessage> wait(Pred pred, std::chrono::milliseconds timeout) const {
    const auto until = std::chrono::steady_clock::now() + timeout;
    auto m = messages();
    while (!pred(m) && std::chrono::steady_clock::now() < until) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      m = messages();
    }
    return m;
  }
  std::string log() const;

 private:
  TempDir dir_;
  std::unique_ptr<Child> proc_;
};

/// mosquitto_pub -q 1; returns its exit status (output in `out`).  Empty user: anonymous.
int mqtt_publish(const MqttBroker& broker, const std::string& user, const std::string& topic,
                 const std::string& payload, std::string* out = nullptr, bool tls = false,
                 int port = 0);

/// Validates every payload errsep published against schema/mqtt-messages.schema.json (the
/// plant's own cmd/scan messages are skipped); "" when all are valid, else the failures.
std::string validate_payloads(const std::vector<MqttMessage>& messages);

/// Field `key` of a JSON payload as text ("" when absent): strings bare, other values dumped.
std::string json_field(const std::string& payload, const std::string& key);

/// The [mqtt] table of a machine config for `machine` on this broker (user = machine).
std::string mqtt_table(const MqttBroker& broker, const std::string& machine, bool commands,
                       bool tls = false, const std::filesystem::path& queue_dir = {});

/// tests/apps/daemon_machine.toml with the sensor bus's response timeout raised to 200 ms.
std::string mqtt_machine_toml();
/// A daemon rig whose machine config is mqtt_machine_toml() plus `mqtt_toml`.
void use_mqtt_config(DaemonRig& rig, const std::string& mqtt_toml);

}  // namespace errsep::test

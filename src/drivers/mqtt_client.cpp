#include "errsep/drivers/mqtt_client.hpp"

#include <mosquitto.h>

#include <mutex>
#include <stdexcept>

namespace errsep::drivers {

bool MqttClientOptions::is_valid(std::string* why) const {
  auto bad = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (host.empty()) return bad("host is empty");
  if (port < 1 || port > 65535) return bad("port = " + std::to_string(port) + ": not in 1..65535");
  if (client_id.empty() || client_id.size() > 128)
    return bad("client_id must have 1 to 128 characters");
  if (keepalive_s < 5 || keepalive_s > 65535)
    return bad("keepalive_s = " + std::to_string(keepalive_s) + ": not in 5..65535");
  if (tls_cert_file.empty() != tls_key_file.empty())
    return bad("tls_cert_file and tls_key_file go together");
  if (!tls_cert_file.empty() && tls_ca_file.empty())
    return bad("a client certificate needs tls_ca_file");
  if (will_qos < 0 || will_qos > 2) return bad("will_qos must be 0, 1 or 2");
  return true;
}

namespace {
void lib_init_once() {
  static std::once_flag once;
  // Process-wide (OpenSSL set-up); libmosquitto's cleanup at exit is not needed.
  std::call_once(once, [] { mosquitto_lib_init(); });
}
}  // namespace

struct MqttCallbacks {
  static void on_connect(struct mosquitto*, void* obj, int rc) {
    auto* c = static_cast<MqttClient*>(obj);
    c->connack_ = rc;
    c->connected_ = rc == 0;
    if (rc != 0) c->last_error_ = std::string("broker refused: ") + mosquitto_connack_string(rc);
  }
  static void on_disconnect(struct mosquitto*, void* obj, int rc) {
    auto* c = static_cast<MqttClient*>(obj);
    c->connected_ = false;
    if (rc != 0) c->last_error_ = std::string("connection lost: ") + mosquitto_strerror(rc);
  }
  static void on_publish(struct mosquitto*, void* obj, int mid) {
    auto* c = static_cast<MqttClient*>(obj);
    if (c->on_ack) c->on_ack(mid);
  }
  static void on_message(struct mosquitto*, void* obj, const struct mosquitto_message* m) {
    auto* c = static_cast<MqttClient*>(obj);
    if (!c->on_message || !m || !m->topic) return;
    const std::string payload(static_cast<const char*>(m->payload),
                              m->payload ? static_cast<std::size_t>(m->payloadlen) : 0);
    c->on_message(m->topic, payload);
  }
};

MqttClient::MqttClient(MqttClientOptions opts) : opts_(std::move(opts)) {
  std::string why;
  if (!opts_.is_valid(&why)) throw std::invalid_argument("MQTT client options: " + why);
  lib_init_once();
}

MqttClient::~MqttClient() {
  destroy();
}

void MqttClient::destroy() noexcept {
  if (mosq_) mosquitto_destroy(mosq_);  // closes the socket; no DISCONNECT, so a will fires
  mosq_ = nullptr;
  connected_ = false;
}

bool MqttClient::connect(std::chrono::milliseconds timeout, std::string* why,
                         const std::atomic<bool>* abort) {
  destroy();
  auto fail = [&](const std::string& m) {
    last_error_ = m;
    if (why) *why = m;
    destroy();
    return false;
  };
  mosq_ = mosquitto_new(opts_.client_id.c_str(), true, this);
  if (!mosq_) return fail("mosquitto_new failed (out of memory)");
  mosquitto_connect_callback_set(mosq_, &MqttCallbacks::on_connect);
  mosquitto_disconnect_callback_set(mosq_, &MqttCallbacks::on_disconnect);
  mosquitto_publish_callback_set(mosq_, &MqttCallbacks::on_publish);
  mosquitto_message_callback_set(mosq_, &MqttCallbacks::on_message);
  int rc = MOSQ_ERR_SUCCESS;
  if (!opts_.username.empty()) {
    rc = mosquitto_username_pw_set(mosq_, opts_.username.c_str(),
                                   opts_.password.empty() ? nullptr : opts_.password.c_str());
    if (rc != MOSQ_ERR_SUCCESS) return fail(std::string("username: ") + mosquitto_strerror(rc));
  }
  if (!opts_.tls_ca_file.empty()) {
    rc = mosquitto_tls_set(mosq_, opts_.tls_ca_file.c_str(), nullptr,
                           opts_.tls_cert_file.empty() ? nullptr : opts_.tls_cert_file.c_str(),
                           opts_.tls_key_file.empty() ? nullptr : opts_.tls_key_file.c_str(),
                           nullptr);
    if (rc != MOSQ_ERR_SUCCESS)
      return fail("TLS files (" + opts_.tls_ca_file.string() + "): " + mosquitto_strerror(rc));
  }
  if (!opts_.will_topic.empty()) {
    rc = mosquitto_will_set(mosq_, opts_.will_topic.c_str(),
                            static_cast<int>(opts_.will_payload.size()), opts_.will_payload.data(),
                            opts_.will_qos, opts_.will_retain);
    if (rc != MOSQ_ERR_SUCCESS) return fail(std::string("last will: ") + mosquitto_strerror(rc));
  }
  connack_ = -1;
  connected_ = false;
  // Non-blocking: a host that does not answer SYNs cannot hold the caller (a stop) for the
  // kernel's connect timeout; the wait below is bounded by `timeout` and `abort`.
  rc = mosquitto_connect_async(mosq_, opts_.host.c_str(), opts_.port, opts_.keepalive_s);
  if (rc != MOSQ_ERR_SUCCESS) {
    std::string m = "connect to " + opts_.host + ":" + std::to_string(opts_.port) + ": " +
                    (rc == MOSQ_ERR_ERRNO ? std::string("system error") : mosquitto_strerror(rc));
    if (rc == MOSQ_ERR_TLS) m += " (TLS handshake failed)";
    return fail(m);
  }
  const auto until = std::chrono::steady_clock::now() + timeout;
  while (connack_ < 0 && std::chrono::steady_clock::now() < until && !(abort && abort->load())) {
    rc = mosquitto_loop(mosq_, 50, 1);
    if (rc != MOSQ_ERR_SUCCESS && connack_ < 0) {
      std::string m = "connect to " + opts_.host + ":" + std::to_string(opts_.port) + ": " +
                      mosquitto_strerror(rc);
      if (rc == MOSQ_ERR_TLS) m += " (TLS handshake failed)";
      if (rc == MOSQ_ERR_CONN_LOST && !opts_.tls_ca_file.empty())
        m += " (TLS configured: is the port a TLS listener?)";
      return fail(m);
    }
  }
  if (connack_ < 0)
    return fail("connect to " + opts_.host + ":" + std::to_string(opts_.port) +
                ": no CONNACK within " + std::to_string(timeout.count()) + " ms");
  if (connack_ != 0) return fail(last_error_);
  return true;
}

int MqttClient::publish(const std::string& topic, const std::string& payload, int qos, bool retain,
                        std::string* why) {
  if (!mosq_ || !connected_) {
    if (why) *why = "not connected";
    return 0;
  }
  int mid = 0;
  const int rc = mosquitto_publish(mosq_, &mid, topic.c_str(), static_cast<int>(payload.size()),
                                   payload.data(), qos, retain);
  if (rc != MOSQ_ERR_SUCCESS) {
    if (why) *why = std::string("publish ") + topic + ": " + mosquitto_strerror(rc);
    return 0;
  }
  return mid;
}

bool MqttClient::subscribe(const std::string& topic, int qos, std::string* why) {
  if (!mosq_ || !connected_) {
    if (why) *why = "not connected";
    return false;
  }
  const int rc = mosquitto_subscribe(mosq_, nullptr, topic.c_str(), qos);
  if (rc != MOSQ_ERR_SUCCESS) {
    if (why) *why = std::string("subscribe ") + topic + ": " + mosquitto_strerror(rc);
    return false;
  }
  return true;
}

void MqttClient::loop(std::chrono::milliseconds timeout) {
  if (!mosq_) return;
  const int rc = mosquitto_loop(mosq_, static_cast<int>(timeout.count()), 1);
  if (rc != MOSQ_ERR_SUCCESS) {
    if (connected_ || last_error_.empty())
      last_error_ = std::string("connection lost: ") + mosquitto_strerror(rc);
    connected_ = false;
  }
}

void MqttClient::disconnect() {
  if (mosq_ && connected_) {
    mosquitto_disconnect(mosq_);
    mosquitto_loop(mosq_, 50, 1);  // sends the DISCONNECT
  }
  destroy();
}

}  // namespace errsep::drivers

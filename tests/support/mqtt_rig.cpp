#include "support/mqtt_rig.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace errsep::test {
namespace {

std::string read_all(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void write_text(const std::filesystem::path& p, const std::string& s) {
  std::ofstream out(p, std::ios::binary);
  out << s;
  if (!out) throw std::runtime_error("cannot write " + p.string());
}

/// A loopback port that was free a moment ago (the broker binds it next).
int free_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  socklen_t len = sizeof a;
  if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) != 0)
    throw std::runtime_error("cannot find a free loopback port");
  ::close(fd);
  return ntohs(a.sin_port);
}

bool port_accepts(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  const bool ok = fd >= 0 && ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  if (fd >= 0) ::close(fd);
  return ok;
}

std::string sh_quote(const std::string& s) {
  std::string r = "'";
  for (char c : s)
    r += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return r + "'";
}

}  // namespace

std::string mqtt_tools_missing() {
  for (const char* exe : {"/usr/sbin/mosquitto", "/usr/bin/mosquitto_sub", "/usr/bin/mosquitto_pub",
                          "/usr/bin/mosquitto_passwd", "/usr/bin/openssl", "/usr/bin/python3"})
    if (::access(exe, X_OK) != 0)
      return std::string(exe) +
             " is missing (Debian packages mosquitto, mosquitto-clients, openssl)";
  if (run_command("/usr/bin/python3 -c 'import jsonschema'") != 0)
    return "python3-jsonschema is missing (Debian package python3-jsonschema)";
  return {};
}

MqttBroker::MqttBroker(MqttBrokerOptions opts) : opts_(std::move(opts)) {
  const auto d = dir_.path();
  std::filesystem::create_directories(d / "persist");
  // Password file: a user per machine, the plant's command client, a read-only viewer.
  std::vector<std::string> users = opts_.machines;
  users.push_back("plant");
  users.push_back("viewer");
  std::string out;
  for (std::size_t i = 0; i < users.size(); ++i) {
    const std::string cmd = "/usr/bin/mosquitto_passwd " + std::string(i == 0 ? "-c " : "") +
                            "-b " + sh_quote((d / "passwd").string()) + " " + sh_quote(users[i]) +
                            " " + sh_quote(users[i] + "-pw");
    if (run_command(cmd, &out) != 0) throw std::runtime_error("mosquitto_passwd failed: " + out);
    write_text(password_file(users[i]), users[i] + "-pw\n");
  }
  // The ACL README.md recommends to a plant (prefix "errsep").
  write_text(d / "acl",
             "pattern write errsep/%u/status\n"
             "pattern write errsep/%u/scan/+\n"
             "pattern write errsep/%u/alarm\n"
             "pattern write errsep/%u/cmd/scan/reply\n"
             "pattern read errsep/%u/cmd/scan\n"
             "\n"
             "user plant\n"
             "topic write errsep/+/cmd/scan\n"
             "topic read errsep/#\n"
             "\n"
             "user viewer\n"
             "topic read errsep/#\n");
  if (opts_.tls) {
    // A CA and a server certificate for 127.0.0.1 (P-256 keys: fast), made here.
    write_text(d / "san.ext", "subjectAltName=IP:127.0.0.1\n");
    const std::string q = sh_quote(d.string());
    const std::string cmd =
        "cd " + q +
        " && /usr/bin/openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes "
        "-keyout ca.key -out ca.crt -days 2 -subj '/CN=errsep test CA'"
        " && /usr/bin/openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes "
        "-keyout server.key -out server.csr -subj '/CN=127.0.0.1'"
        " && /usr/bin/openssl x509 -req -in server.csr -CA ca.crt -CAkey ca.key -CAcreateserial "
        "-out server.crt -days 2 -extfile san.ext";
    if (run_command(cmd, &out) != 0) throw std::runtime_error("openssl failed: " + out);
  }
  port_ = opts_.plain ? free_port() : 0;
  tls_port_ = opts_.tls ? free_port() : 0;
  std::ostringstream conf;
  conf << "per_listener_settings false\n"
       << "allow_anonymous false\n"
       << "password_file " << (d / "passwd").string() << "\n"
       << "acl_file " << (d / "acl").string() << "\n"
       << "persistence " << (opts_.persistence ? "true" : "false") << "\n"
       << "persistence_location " << (d / "persist").string() << "/\n"
       << "log_dest stderr\n"
       << "log_type error\nlog_type warning\nlog_type notice\nlog_type information\n"
       << "connection_messages true\n";
  // As root mosquitto would switch to user 'mosquitto', who cannot read the test's files.
  if (::geteuid() == 0) conf << "user root\n";
  if (opts_.plain) conf << "listener " << port_ << " 127.0.0.1\n";
  if (opts_.tls)
    conf << "listener " << tls_port_ << " 127.0.0.1\n"
         << "cafile " << (d / "ca.crt").string() << "\n"
         << "certfile " << (d / "server.crt").string() << "\n"
         << "keyfile " << (d / "server.key").string() << "\n";
  write_text(d / "mosquitto.conf", conf.str());
}

MqttBroker::~MqttBroker() {
  if (proc_) proc_->signal(SIGKILL);
}

std::filesystem::path MqttBroker::password_file(const std::string& user) const {
  return dir_ / (user + ".password");
}

void MqttBroker::start() {
  proc_ = std::make_unique<Child>(
      std::vector<std::string>{"/usr/sbin/mosquitto", "-c", (dir_ / "mosquitto.conf").string()},
      std::vector<std::string>{}, dir_ / "mosquitto.log");
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (std::chrono::steady_clock::now() < until) {
    if (!proc_->running()) break;
    if ((!opts_.plain || port_accepts(port_)) && (!opts_.tls || port_accepts(tls_port_))) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  throw std::runtime_error("mosquitto did not start listening:\n" + log());
}

void MqttBroker::stop() {
  if (!proc_) return;
  proc_->signal(SIGTERM);
  if (!proc_->wait(std::chrono::seconds(10))) proc_->signal(SIGKILL);
  proc_->wait(std::chrono::seconds(5));
  proc_.reset();
}

void MqttBroker::signal(int sig) {
  if (proc_) proc_->signal(sig);
}

std::string MqttBroker::log() const {
  return read_all(dir_ / "mosquitto.log");
}

MqttSubscriber::MqttSubscriber(const MqttBroker& broker, const std::string& user,
                               const std::string& topic, const std::string& session) {
  std::string cmd = "exec /usr/bin/mosquitto_sub -h 127.0.0.1 -p " + std::to_string(broker.port()) +
                    " -u " + sh_quote(user) + " -P " + sh_quote(user + "-pw") + " -q 1 -t " +
                    sh_quote(topic) + " -F '%t %r %p'";
  if (!session.empty()) cmd += " -c -i " + sh_quote(session);
  cmd += " > " + sh_quote((dir_ / "messages.txt").string());
  proc_ = std::make_unique<Child>(std::vector<std::string>{"/bin/sh", "-c", cmd},
                                  std::vector<std::string>{}, dir_ / "sub.log");
  // Subscribed once the broker logs it; a short wait is enough on loopback.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
}

MqttSubscriber::~MqttSubscriber() {
  if (proc_) proc_->signal(SIGTERM);
}

std::vector<MqttMessage> MqttSubscriber::messages() const {
  std::vector<MqttMessage> out;
  std::istringstream is(read_all(dir_ / "messages.txt"));
  std::string line;
  while (std::getline(is, line)) {
    const auto a = line.find(' ');
    if (a == std::string::npos || a + 2 >= line.size()) continue;
    MqttMessage m;
    m.topic = line.substr(0, a);
    m.retained = line[a + 1] == '1';
    m.payload = line.substr(a + 3);
    out.push_back(std::move(m));
  }
  return out;
}

std::string MqttSubscriber::log() const {
  return read_all(dir_ / "sub.log");
}

int mqtt_publish(const MqttBroker& broker, const std::string& user, const std::string& topic,
                 const std::string& payload, std::string* out, bool tls, int port) {
  std::string cmd = "/usr/bin/mosquitto_pub -h 127.0.0.1 -q 1 -p " +
                    std::to_string(port  ? port
                                   : tls ? broker.tls_port()
                                         : broker.port()) +
                    " -t " + sh_quote(topic) + " -m " + sh_quote(payload);
  if (!user.empty()) cmd += " -u " + sh_quote(user) + " -P " + sh_quote(user + "-pw");
  if (tls) cmd += " --cafile " + sh_quote(broker.ca_file().string());
  return run_command(cmd, out);
}

std::string validate_payloads(const std::vector<MqttMessage>& messages) {
  TempDir d;
  std::string all;
  for (const auto& m : messages) {
    // What the plant sends on cmd/scan is the plant's, not errsep's (checked by errsep instead).
    const std::string tail = "/cmd/scan";
    if (m.topic.size() >= tail.size() &&
        m.topic.compare(m.topic.size() - tail.size(), tail.size(), tail) == 0)
      continue;
    all += m.payload + "\n";
  }
  write_text(d / "payloads.txt", all);
  std::string out;
  const int rc = run_command(
      "/usr/bin/python3 " + sh_quote((source_dir() / "tests/support/validate_mqtt.py").string()) +
          " " + sh_quote((source_dir() / "schema/mqtt-messages.schema.json").string()) + " " +
          sh_quote((d / "payloads.txt").string()),
      &out);
  return rc == 0 ? std::string() : out;
}

std::string json_field(const std::string& payload, const std::string& key) {
  const auto j = nlohmann::json::parse(payload, nullptr, false);
  if (j.is_discarded() || !j.is_object() || !j.contains(key)) return {};
  const auto& v = j.at(key);
  return v.is_string() ? v.get<std::string>() : v.dump();
}

std::string mqtt_table(const MqttBroker& broker, const std::string& machine, bool commands,
                       bool tls, const std::filesystem::path& queue_dir) {
  std::ostringstream t;
  t << "\n[mqtt]\n"
    << "host = \"127.0.0.1\"\n"
    << "port = " << (tls ? broker.tls_port() : broker.port()) << "\n"
    << "machine = \"" << machine << "\"\n"
    << "topic_prefix = \"errsep\"\n"
    << "username = \"" << machine << "\"\n"
    << "password_file = \"" << broker.password_file(machine).string() << "\"\n"
    << "keepalive_s = 5\n"
    << "commands = " << (commands ? "true" : "false") << "\n";
  if (tls) t << "tls_ca_file = \"" << broker.ca_file().string() << "\"\n";
  if (!queue_dir.empty()) t << "queue_dir = \"" << queue_dir.string() << "\"\n";
  return t.str();
}

std::string mqtt_machine_toml() {
  // The sensor bus's 20 ms response timeout of the daemon tests, raised: eight services and
  // their simulators on two loaded cores (under ASan too) miss 20 ms now and then, and a
  // device fault is not what these tests are about (tests/drivers/modbus_faults.cpp is).
  std::string t = read_all(source_dir() / "tests/apps/daemon_machine.toml");
  const std::string from = "response_timeout_ms = 20\n";
  const auto p = t.find(from);
  if (p == std::string::npos)
    throw std::runtime_error("daemon_machine.toml: no 'response_timeout_ms = 20' to raise");
  return t.replace(p, from.size(), "response_timeout_ms = 200\n");
}

void use_mqtt_config(DaemonRig& rig, const std::string& mqtt_toml) {
  const auto cfg = rig.tmp / "machine.toml";
  write_text(cfg, mqtt_machine_toml() + mqtt_toml);
  rig.config = cfg;
}

}  // namespace errsep::test

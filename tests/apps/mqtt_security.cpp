// Security of the MQTT side, against a real broker with a password file and the ACL README.md
// recommends:
//  - a client without the password (anonymous, or a wrong one) cannot even connect, and a
//    client with a password but no write right on cmd/scan (viewer) is dropped by the broker:
//    no scan starts;
//  - a malformed cmd/scan payload is refused with its reason on cmd/scan/reply and nothing else
//    happens (no scan, the daemon stays idle); a request while a scan runs is refused with the
//    reason ("a scan is running"), as the Modbus coil is;
//  - with TLS configured, errsep connects only through TLS: to a plain-TCP listener it does not
//    connect (no fall-back), and a plain-TCP client is refused by the TLS listener.
#include <signal.h>
#include <sys/wait.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <iostream>
#include <thread>

#include "errsep/service/plant_publisher.hpp"
#include "support/daemon_rig.hpp"
#include "support/mqtt_rig.hpp"

using namespace errsep;
using namespace std::chrono_literals;

namespace {

std::vector<test::MqttMessage> replies(const std::vector<test::MqttMessage>& ms) {
  std::vector<test::MqttMessage> r;
  for (const auto& m : ms)
    if (m.topic == "errsep/m0/cmd/scan/reply") r.push_back(m);
  return r;
}

bool any_store_file(const std::filesystem::path& dir) {
  if (!std::filesystem::exists(dir)) return false;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (io::parse_store_name(e.path())) return true;
  return false;
}

}  // namespace

TEST_CASE(
    "security: commands need the password and the ACL, malformed and busy requests are refused "
    "with a reason") {
  if (const auto why = test::mqtt_tools_missing(); !why.empty()) {
    std::cout << "SKIPPED: " << why << "\n";
    return;
  }
  test::MqttBroker broker({{"m0"}, true, false, false});
  broker.start();
  test::MqttSubscriber sub(broker, "viewer", "errsep/#");
  test::DaemonRig rig;
  test::use_mqtt_config(rig, test::mqtt_table(broker, "m0", true));
  rig.devsim.start(rig.config, rig.tmp / "devsim.log");
  rig.start_daemon();
  INFO(rig.logs() << "\nbroker:\n" << broker.log());
  REQUIRE(rig.notify->wait_for("READY=1", 30s));
  const auto idle = sub.wait(
      [](const auto& ms) {
        for (const auto& m : ms)
          if (m.topic == "errsep/m0/status" && test::json_field(m.payload, "state") == "idle")
            return true;
        return false;
      },
      20s);
  REQUIRE_FALSE(idle.empty());
  const std::string cmd_topic = "errsep/m0/cmd/scan";

  // No password: the broker refuses the connection (mosquitto_pub exits non-zero).
  std::string out;
  CHECK(test::mqtt_publish(broker, "", cmd_topic, R"({"request_id":"anon"})", &out) != 0);
  INFO(out);
  CHECK(out.find("not authorised") != std::string::npos);
  // A wrong password: refused too.
  CHECK(test::run_command("/usr/bin/mosquitto_pub -h 127.0.0.1 -q 1 -p " +
                              std::to_string(broker.port()) + " -u plant -P wrong -t " + cmd_topic +
                              " -m '{\"request_id\":\"x\"}'",
                          &out) != 0);
  // A user with a password but no write right on cmd/scan: the broker drops the message.
  CHECK(test::mqtt_publish(broker, "viewer", cmd_topic, R"({"request_id":"viewer"})") == 0);

  // Malformed payloads from the plant's client: each refused with its reason.
  const std::vector<std::string> bad = {
      "scan please", R"({"request_id": 5})", R"({"request_id":"a","extra":1})", "[]",
      "{}",          R"({"request_id":""})"};
  for (const auto& p : bad)
    CHECK(test::mqtt_publish(broker, "plant", cmd_topic, p) == 0);
  auto msgs = sub.wait([&](const auto& ms) { return replies(ms).size() >= bad.size(); }, 20s);
  auto rep = replies(msgs);
  CHECK(rep.size() == bad.size());  // none for the anonymous, wrong-password or viewer requests
  for (const auto& r : rep) {
    INFO(r.payload);
    CHECK(test::json_field(r.payload, "accepted") == "false");
    CHECK(test::json_field(r.payload, "reason").rfind("malformed command: ", 0) == 0);
  }
  // Nothing else happened: no scan, still idle.
  std::this_thread::sleep_for(1s);
  CHECK_FALSE(any_store_file(rig.results));
  auto regs = rig.registers();
  REQUIRE(regs.size() == test::kRegisterCount);
  CHECK(regs[test::reg_state] == 1);
  CHECK(regs[test::reg_scans_completed] == 0);
  CHECK(regs[test::reg_scan_id] == 0);

  // A well-formed request is accepted; a second one while the scan runs is refused with the
  // reason the Modbus coil gets.
  CHECK(test::mqtt_publish(broker, "plant", cmd_topic, R"({"request_id":"first"})") == 0);
  msgs = sub.wait([&](const auto& ms) { return replies(ms).size() >= bad.size() + 1; }, 20s);
  rep = replies(msgs);
  REQUIRE(rep.size() == bad.size() + 1);
  CHECK(test::json_field(rep.back().payload, "request_id") == "first");
  CHECK(test::json_field(rep.back().payload, "accepted") == "true");
  CHECK(test::mqtt_publish(broker, "plant", cmd_topic, R"({"request_id":"second"})") == 0);
  msgs = sub.wait([&](const auto& ms) { return replies(ms).size() >= bad.size() + 2; }, 20s);
  rep = replies(msgs);
  REQUIRE(rep.size() == bad.size() + 2);
  INFO(rep.back().payload);
  CHECK(test::json_field(rep.back().payload, "request_id") == "second");
  CHECK(test::json_field(rep.back().payload, "accepted") == "false");
  const std::string reason = test::json_field(rep.back().payload, "reason");
  CHECK((reason.find("a scan is running") != std::string::npos ||
         reason.find("a scan is about to start") != std::string::npos));
  // Exactly one scan comes of it.
  regs =
      rig.wait_regs([](const auto& r) { return r[test::reg_last_scan_id] == 1 && r[0] == 1; }, 30s);
  REQUIRE(regs.size() == test::kRegisterCount);
  // (complete, or ended by a device fault if the loaded machine starves the simulator)
  CHECK((regs[test::reg_last_outcome] == 1 || regs[test::reg_last_outcome] == 3));
  std::this_thread::sleep_for(500ms);
  regs = rig.registers();
  REQUIRE(regs.size() == test::kRegisterCount);
  CHECK(regs[test::reg_last_scan_id] == 1);  // the refused request started nothing
  CHECK(regs[test::reg_scan_id] == 0);
  CHECK(regs[test::reg_trigger_source] == 4);  // mqtt
  msgs = sub.wait(
      [](const auto& ms) {
        for (const auto& m : ms)
          if (m.topic.rfind("errsep/m0/scan/", 0) == 0) return true;
        return false;
      },
      20s);
  // A clean stop: exit 0 (no sanitizer report under ASan), the retained status says offline.
  rig.daemon->signal(SIGTERM);
  const auto st = rig.daemon->wait(15s);
  REQUIRE(st);
  CHECK(WIFEXITED(*st));
  CHECK(WEXITSTATUS(*st) == 0);
  CHECK(rig.logs().find("Sanitizer") == std::string::npos);
  CHECK(rig.logs().find("runtime error") == std::string::npos);
  msgs = sub.wait(
      [](const auto& ms) {
        return !ms.empty() && ms.back().topic == "errsep/m0/status" &&
               test::json_field(ms.back().payload, "state") == "offline";
      },
      10s);
  REQUIRE_FALSE(msgs.empty());
  CHECK(msgs.back().topic == "errsep/m0/status");
  CHECK(test::json_field(msgs.back().payload, "message") == "stopped");
  const std::string invalid = test::validate_payloads(msgs);
  INFO(invalid);
  CHECK(invalid.empty());
}

TEST_CASE(
    "security: with TLS configured errsep connects through TLS only, plain TCP to the TLS listener "
    "is refused") {
  if (const auto why = test::mqtt_tools_missing(); !why.empty()) {
    std::cout << "SKIPPED: " << why << "\n";
    return;
  }
  test::MqttBroker broker({{"m0"}, true, true, false});
  broker.start();
  INFO("broker:\n" << broker.log());
  test::TempDir tmp;
  auto publisher = [&](int port, const std::string& queue) {
    service::PlantPublisherOptions o;
    o.mqtt.host = "127.0.0.1";
    o.mqtt.port = port;
    o.mqtt.machine = "m0";
    o.mqtt.username = "m0";
    o.mqtt.password_file = broker.password_file("m0");
    o.mqtt.tls_ca_file = broker.ca_file();
    o.mqtt.keepalive_s = 5;
    o.queue_dir = tmp / queue;
    o.connect_timeout = 2000ms;
    return std::make_unique<service::PlantPublisher>(
        o, [] { return io::StatusMessage{"m0", true, "idle", "test", "", 0, ""}; });
  };
  // TLS to the TLS listener: connects, and a queued message is acknowledged and removed.
  auto ok = publisher(broker.tls_port(), "q-tls");
  ok->queue("alarm", R"({"type":"alarm"})");
  ok->start();
  const auto until = std::chrono::steady_clock::now() + 20s;
  while ((ok->counters().acknowledged < 1 || ok->queued() > 0) &&
         std::chrono::steady_clock::now() < until)
    std::this_thread::sleep_for(20ms);
  CHECK(ok->counters().acknowledged == 1);
  CHECK(ok->queued() == 0);
  ok->stop();
  // TLS configured, pointed at the plain-TCP listener: never connected, nothing sent, the
  // message stays queued.
  auto plain = publisher(broker.port(), "q-plain");
  plain->queue("alarm", R"({"type":"alarm"})");
  plain->start();
  std::this_thread::sleep_for(3s);
  const auto c = plain->counters();
  plain->stop();
  INFO(c.last_error);
  CHECK(c.connects == 0);
  CHECK(c.connect_failures >= 1);
  CHECK_FALSE(c.last_error.empty());
  CHECK(c.acknowledged == 0);
  CHECK(plain->queued() == 1);
  // A plain-TCP client on the TLS listener is refused; with the CA it gets through.
  std::string out;
  CHECK(test::mqtt_publish(broker, "plant", "errsep/m0/cmd/scan", "{}", &out, false,
                           broker.tls_port()) != 0);
  CHECK(test::mqtt_publish(broker, "plant", "errsep/m0/cmd/scan", "{}", &out, true) == 0);
}

// The plant publisher against a real broker (started by the test), in process:
//  - a broker that blocks (SIGSTOP) mid-publish: nothing is acknowledged, nothing leaves the
//    disk queue; once it runs again every message arrives and the queue empties;
//  - a second publisher on the same queue directory (a restart) sends what the first left;
//  - the options and a missing password file are refused with a clear message.
#include "errsep/service/plant_publisher.hpp"

#include <signal.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <iostream>
#include <set>
#include <thread>

#include "support/mqtt_rig.hpp"

using namespace errsep;
using namespace std::chrono_literals;

namespace {

service::PlantPublisherOptions options(const test::MqttBroker& b, const std::filesystem::path& q) {
  service::PlantPublisherOptions o;
  o.mqtt.port = b.port();
  o.mqtt.machine = "m0";
  o.mqtt.username = "m0";
  o.mqtt.password_file = b.password_file("m0");
  o.mqtt.keepalive_s = 30;
  o.queue_dir = q;
  return o;
}

bool wait_until(const std::function<bool()>& pred, std::chrono::milliseconds timeout) {
  const auto until = std::chrono::steady_clock::now() + timeout;
  while (!pred()) {
    if (std::chrono::steady_clock::now() >= until) return false;
    std::this_thread::sleep_for(20ms);
  }
  return true;
}

}  // namespace

TEST_CASE(
    "publisher: a blocked broker delays messages and loses none, a restart sends what is left") {
  if (const auto why = test::mqtt_tools_missing(); !why.empty()) {
    std::cout << "SKIPPED: " << why << "\n";
    return;
  }
  test::MqttBroker broker({{"m0"}, true, false, false});
  broker.start();
  test::MqttSubscriber sub(broker, "viewer", "errsep/m0/alarm");
  test::TempDir tmp;
  {
    service::PlantPublisher pub(options(broker, tmp / "q"), {});
    pub.start();
    REQUIRE(wait_until([&] { return pub.counters().connected; }, 10s));
    broker.signal(SIGSTOP);
    for (int i = 0; i < 5; ++i)
      pub.queue("alarm", "{\"n\":" + std::to_string(i) + "}");
    std::this_thread::sleep_for(1500ms);
    CHECK(pub.counters().acknowledged == 0);
    CHECK(pub.queued() == 5);  // published, not acknowledged: still on disk
    broker.signal(SIGCONT);
    CHECK(wait_until([&] { return pub.queued() == 0; }, 20s));
    CHECK(pub.counters().acknowledged == 5);
    // Left for the next publisher: queued while this one stops.
    pub.stop(0ms);
    pub.queue("alarm", R"({"n":5})");
    pub.queue("alarm", R"({"n":6})");
    CHECK(pub.queued() == 2);
  }
  service::PlantPublisher again(options(broker, tmp / "q"), {});
  again.start();
  CHECK(wait_until([&] { return again.queued() == 0; }, 20s));
  const auto msgs = sub.wait([](const auto& ms) { return ms.size() >= 7; }, 20s);
  std::set<std::string> got;
  for (const auto& m : msgs)
    got.insert(m.payload);
  CHECK(got.size() == 7);  // each of the 7 at least once
  for (int i = 0; i < 7; ++i)
    CHECK(got.count("{\"n\":" + std::to_string(i) + "}") == 1);
}

TEST_CASE("publisher: invalid options and an unreadable password file are refused clearly") {
  test::TempDir tmp;
  service::PlantPublisherOptions o;
  o.queue_dir = tmp / "q";
  CHECK_THROWS_WITH(service::PlantPublisher(o, {}), Catch::Contains("mqtt.machine is empty"));
  o.mqtt.machine = "m0";
  o.max_inflight = 0;
  CHECK_THROWS_WITH(service::PlantPublisher(o, {}), Catch::Contains("max_inflight = 0"));
  o.max_inflight = 20;
  o.mqtt.username = "m0";
  o.mqtt.password_file = tmp / "missing.password";
  CHECK_THROWS_WITH(service::PlantPublisher(o, {}),
                    Catch::Contains("password_file") && Catch::Contains("missing.password"));
  o.mqtt.password_file.clear();
  o.mqtt.tls_ca_file = tmp / "missing-ca.crt";
  CHECK_THROWS_WITH(service::PlantPublisher(o, {}), Catch::Contains("missing-ca.crt"));
}

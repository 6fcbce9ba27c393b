// errsep-scan with [mqtt]: the scan's summary is published after its files are written; with
// the broker down the scan still succeeds, its summary waits in the disk queue beside the output
// directory and goes out with the next run.  Against a real broker started by the test.
#include <catch2/catch.hpp>
#include <chrono>
#include <fstream>
#include <iostream>
#include <set>

#include "errsep/io/message_queue.hpp"
#include "support/daemon_rig.hpp"
#include "support/mqtt_rig.hpp"

using namespace errsep;
using namespace std::chrono_literals;

TEST_CASE("errsep-scan publishes its summary - broker down: queued on disk, sent by the next run") {
  if (const auto why = test::mqtt_tools_missing(); !why.empty()) {
    std::cout << "SKIPPED: " << why << "\n";
    return;
  }
  test::MqttBroker broker({{"m0"}, true, false, true});
  broker.start();
  test::MqttSubscriber sub(broker, "viewer", "errsep/#", "scan-app-subscriber");
  test::TempDir tmp;
  {
    std::ofstream out(tmp / "machine.toml");
    out << test::mqtt_machine_toml() << test::mqtt_table(broker, "m0", false);
  }
  auto scan = [&](const std::string& out_dir, const std::string& extra, std::string* output) {
    return test::run_command(test::app_path("scan").string() + " -c " +
                                 (tmp / "machine.toml").string() + " --out " +
                                 (tmp / out_dir).string() + " " + extra,
                             output);
  };
  auto scan_topics = [](const std::vector<test::MqttMessage>& ms) {
    std::set<std::string> t;
    for (const auto& m : ms)
      if (m.topic.rfind("errsep/m0/scan/", 0) == 0) t.insert(m.topic);
    return t;
  };
  std::string out;
  REQUIRE(scan("out1", "", &out) == 0);
  INFO(out);
  CHECK(out.find("delivered") != std::string::npos);
  auto msgs = sub.wait([&](const auto& ms) { return scan_topics(ms).size() >= 1; }, 20s);
  REQUIRE(scan_topics(msgs).size() == 1);
  CHECK(io::MessageQueue(tmp / "mqtt-queue").size() == 0);

  // Broker down: the scan succeeds, its summary stays queued.
  broker.stop();
  REQUIRE(scan("out2", "--mqtt-wait-s 1", &out) == 0);
  INFO(out);
  CHECK(out.find("left queued") != std::string::npos);
  CHECK(io::MessageQueue(tmp / "mqtt-queue").size() == 1);
  CHECK(std::filesystem::exists(tmp / "out2" / "motion.csv"));

  // Broker back: the next run sends both.
  broker.start();
  REQUIRE(scan("out3", "", &out) == 0);
  msgs = sub.wait([&](const auto& ms) { return scan_topics(ms).size() >= 3; }, 30s);
  CHECK(scan_topics(msgs).size() == 3);
  CHECK(io::MessageQueue(tmp / "mqtt-queue").size() == 0);
  for (const auto& m : msgs)
    if (m.topic.rfind("errsep/m0/scan/", 0) == 0) {
      INFO(m.payload);
      CHECK(test::json_field(m.payload, "trigger") == "manual");
      CHECK(test::json_field(m.payload, "outcome") == "complete");
      CHECK(test::json_field(m.payload, "straightness") != "null");
    }
  const std::string invalid = test::validate_payloads(msgs);
  INFO(invalid);
  CHECK(invalid.empty());
}

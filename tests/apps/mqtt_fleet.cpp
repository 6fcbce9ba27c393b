// A fleet against one real broker: 8 errsep-daemon services, each with its own device
// simulator, publish to one Mosquitto (started by the test, password file + ACL); the plant's
// client triggers 5 scans on each through <prefix>/<machine>/cmd/scan (refusals while busy are
// answered with a reason and retried).  Every scan's summary arrives, valid against
// schema/mqtt-messages.schema.json, with the scan ids of the local results store; the status
// topic is retained (a late subscriber sees every machine online) and a SIGKILLed service's
// last will turns its retained status to offline.
#include <signal.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <iostream>
#include <map>
#include <set>
#include <thread>

#include "errsep/io/results_store.hpp"
#include "support/daemon_rig.hpp"
#include "support/mqtt_rig.hpp"

using namespace errsep;
using namespace std::chrono_literals;
using clk = std::chrono::steady_clock;

namespace {

/// "errsep/<machine>/<rest>" -> machine, rest.
std::pair<std::string, std::string> split_topic(const std::string& t) {
  const auto a = t.find('/');
  const auto b = a == std::string::npos ? a : t.find('/', a + 1);
  if (b == std::string::npos) return {};
  return {t.substr(a + 1, b - a - 1), t.substr(b + 1)};
}

/// Scans of a results store by stem, with the kinds of their files.
std::map<std::string, std::set<std::string>> stored_scans(const std::filesystem::path& results) {
  std::map<std::string, std::set<std::string>> out;
  for (const auto& e : std::filesystem::directory_iterator(results))
    if (const auto f = io::parse_store_name(e.path())) out[f->stem].insert(f->kind);
  return out;
}

std::set<std::string> stems(const std::map<std::string, std::set<std::string>>& scans) {
  std::set<std::string> s;
  for (const auto& [stem, kinds] : scans)
    s.insert(stem);
  return s;
}

}  // namespace

TEST_CASE(
    "fleet: 8 services x 5 scans, every summary received and valid, status retained, last will "
    "after SIGKILL") {
  if (const auto why = test::mqtt_tools_missing(); !why.empty()) {
    std::cout << "SKIPPED: " << why << "\n";
    return;
  }
  constexpr int kServices = 8, kScans = 5;
  std::vector<std::string> names;
  for (int i = 0; i < kServices; ++i)
    names.push_back("m" + std::to_string(i));
  test::MqttBroker broker({names, true, false, true});
  broker.start();
  test::MqttSubscriber sub(broker, "viewer", "errsep/#");

  std::vector<std::unique_ptr<test::DaemonRig>> rigs;
  for (int i = 0; i < kServices; ++i) {
    auto rig = std::make_unique<test::DaemonRig>();
    // m1 has a straightness tolerance far below the simulated slideway's (~22 um): an alarm
    // per complete scan.
    test::use_mqtt_config(*rig, test::mqtt_table(broker, names[static_cast<std::size_t>(i)], true) +
                                    (i == 1 ? "straightness_tolerance_um = 1.0\n" : ""));
    rig->devsim.start(rig->config, rig->tmp / "devsim.log");
    rig->start_daemon();
    rigs.push_back(std::move(rig));
  }
  auto logs = [&] {
    std::string s = "broker:\n" + broker.log().substr(0, 4000);
    for (const auto& r : rigs)
      s += "\n--- " + r->logs().substr(0, 3000);
    return s;
  };
  // Every service online (birth message on its status topic).
  auto online = [&](const std::vector<test::MqttMessage>& ms) {
    std::set<std::string> on;
    for (const auto& m : ms)
      if (split_topic(m.topic).second == "status" && test::json_field(m.payload, "state") == "idle")
        on.insert(split_topic(m.topic).first);
    return on.size() == names.size();
  };
  auto msgs = sub.wait(online, 60s);
  INFO(logs());
  REQUIRE(online(msgs));

  // The plant triggers kScans scans per machine: one request at a time per machine; a refused
  // one (the daemon is still finishing the last scan) is sent again.
  std::map<std::string, int> sent, accepted;
  std::map<std::string, std::string> outstanding;  // machine -> request id awaiting its reply
  int refused = 0;
  const auto deadline = clk::now() + 150s;
  auto summaries = [&](const std::vector<test::MqttMessage>& ms) {
    std::map<std::string, std::set<std::string>> s;
    for (const auto& m : ms) {
      const auto [machine, rest] = split_topic(m.topic);
      if (rest.rfind("scan/", 0) == 0) s[machine].insert(rest.substr(5));
    }
    return s;
  };
  while (clk::now() < deadline) {
    msgs = sub.messages();
    const auto sums = summaries(msgs);
    bool all = true;
    for (const auto& n : names) {
      // Replies to this machine's outstanding request.
      if (outstanding.count(n)) {
        for (const auto& m : msgs)
          if (m.topic == "errsep/" + n + "/cmd/scan/reply" &&
              test::json_field(m.payload, "request_id") == outstanding[n]) {
            if (test::json_field(m.payload, "accepted") == "true") {
              ++accepted[n];
            } else {
              ++refused;
              INFO("refusal: " << m.payload);
              CHECK(!test::json_field(m.payload, "reason").empty());
            }
            outstanding.erase(n);
            break;
          }
      }
      const int got = sums.count(n) ? static_cast<int>(sums.at(n).size()) : 0;
      if (got < kScans) all = false;
      // Next request once the last accepted scan's summary is in.
      if (!outstanding.count(n) && accepted[n] < kScans && got >= accepted[n]) {
        const std::string id = n + "-req" + std::to_string(++sent[n]);
        std::string out;
        REQUIRE(test::mqtt_publish(broker, "plant", "errsep/" + n + "/cmd/scan",
                                   "{\"request_id\":\"" + id + "\"}", &out) == 0);
        outstanding[n] = id;
      }
    }
    if (all) break;
    std::this_thread::sleep_for(100ms);
  }
  msgs = sub.messages();
  const auto sums = summaries(msgs);
  std::cout << "fleet: " << msgs.size() << " messages, " << refused
            << " refused requests (busy) re-sent\n";
  for (std::size_t i = 0; i < names.size(); ++i) {
    INFO("machine " << names[i] << "\n" << logs());
    REQUIRE(sums.count(names[i]));
    CHECK(static_cast<int>(sums.at(names[i]).size()) == kScans);
    // Exactly the scans of the local store, by scan id.
    CHECK(sums.at(names[i]) == stems(stored_scans(rigs[i]->results)));
  }
  // Every payload received is valid against the schema, and each summary is a complete scan
  // with its straightness and U.
  const std::string invalid = test::validate_payloads(msgs);
  INFO(invalid);
  CHECK(invalid.empty());
  // Each summary says what the local store holds: a complete scan has its result and its
  // straightness; a scan that a device fault ended (the loaded test machine can starve the
  // simulator past the sensor bus's 20 ms timeout) says so and has its alarm.
  std::set<std::string> alarms;
  for (const auto& m : msgs)
    if (split_topic(m.topic).second == "alarm")
      alarms.insert(split_topic(m.topic).first + "/" + test::json_field(m.payload, "scan_id") +
                    "/" + test::json_field(m.payload, "kind"));
  int complete = 0, faulted = 0;
  for (const auto& m : msgs) {
    const auto [machine, rest] = split_topic(m.topic);
    if (rest.rfind("scan/", 0) != 0) continue;
    INFO(m.payload);
    const std::string id = rest.substr(5);
    CHECK(test::json_field(m.payload, "scan_id") == id);
    CHECK(test::json_field(m.payload, "machine") == machine);
    CHECK(test::json_field(m.payload, "trigger") == "mqtt");
    const auto store = stored_scans(rigs[std::stoul(machine.substr(1))]->results);
    REQUIRE(store.count(id));
    if (store.at(id).count("result")) {
      ++complete;
      CHECK(test::json_field(m.payload, "outcome") == "complete");
      CHECK(test::json_field(m.payload, "straightness") != "null");
    } else {
      ++faulted;
      CHECK(test::json_field(m.payload, "outcome") == "device_fault");
      CHECK(alarms.count(machine + "/" + id + "/device_fault") == 1);
    }
  }
  // The tolerance alarms: m1's complete scans, each exceeded beyond its U; nobody else's.
  int tolerance_alarms = 0;
  for (const auto& m : msgs)
    if (split_topic(m.topic).second == "alarm" &&
        test::json_field(m.payload, "kind") == "straightness_tolerance") {
      INFO(m.payload);
      ++tolerance_alarms;
      CHECK(split_topic(m.topic).first == "m1");
      CHECK(test::json_field(m.payload, "proven") == "true");
      const auto store = stored_scans(rigs[1]->results);
      const std::string id = test::json_field(m.payload, "scan_id");
      CHECK((store.count(id) && store.at(id).count("result")));
    }
  int m1_complete = 0;
  for (const auto& [stem, kinds] : stored_scans(rigs[1]->results))
    m1_complete += kinds.count("result") ? 1 : 0;
  CHECK(tolerance_alarms == m1_complete);
  std::cout << "fleet: " << complete << " complete scans, " << faulted
            << " ended by a device fault (summary and alarm published)\n";

  // Retained status: a subscriber that comes now sees every machine's status at once.
  {
    test::MqttSubscriber late(broker, "viewer", "errsep/+/status");
    // The broker sends each machine's retained status on subscription, flagged retained; a
    // service may publish a new status meanwhile, which reaches this subscriber live (retain
    // flag clear, MQTT 3.1.1 §3.3.1.3).  So: each machine's first message is the retained one.
    auto retained_machines = [](const std::vector<test::MqttMessage>& ms) {
      std::set<std::string> first, retained;
      for (const auto& m : ms) {
        const std::string machine = split_topic(m.topic).first;
        if (first.insert(machine).second && m.retained) retained.insert(machine);
      }
      return retained;
    };
    const auto st = late.wait(
        [&](const auto& ms) { return retained_machines(ms).size() >= names.size(); }, 10s);
    std::set<std::string> first;
    for (const auto& m : st) {
      if (!first.insert(split_topic(m.topic).first).second) continue;
      INFO(m.topic << " " << m.payload);
      CHECK(m.retained);
      CHECK(test::json_field(m.payload, "online") == "true");
    }
    CHECK(retained_machines(st).size() == names.size());
  }

  // SIGKILL of one service: the broker publishes its last will, retained.
  rigs[3]->daemon->signal(SIGKILL);
  rigs[3]->daemon->wait(5s);
  auto offline = [](const std::vector<test::MqttMessage>& ms) {
    for (const auto& m : ms)
      if (m.topic == "errsep/m3/status" && test::json_field(m.payload, "state") == "offline")
        return true;
    return false;
  };
  msgs = sub.wait(offline, 20s);
  CHECK(offline(msgs));
  {
    test::MqttSubscriber late(broker, "viewer", "errsep/m3/status");
    const auto st = late.wait([](const auto& ms) { return !ms.empty(); }, 10s);
    REQUIRE(st.size() == 1);
    CHECK(st[0].retained);
    CHECK(test::json_field(st[0].payload, "online") == "false");
    CHECK(test::validate_payloads(st).empty());
  }
}

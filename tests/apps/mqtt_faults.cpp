// Store and forward under faults, against a real broker and two errsep-daemon services whose
// scans are started through their Modbus register maps (so they go on while the broker is
// away): the broker is stopped for part of the run and started again; one service is SIGKILLed
// while its disk queue holds messages, and started again.  Every scan of every local store is
// delivered at least once, nothing else is delivered (duplicates only with the same scan id and
// the same summary), and the local results are byte for byte what they were.
#include <signal.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <fstream>
#include <iostream>
#include <map>
#include <set>
#include <sstream>
#include <thread>

#include "errsep/io/message_queue.hpp"
#include "errsep/io/results_store.hpp"
#include "support/daemon_rig.hpp"
#include "support/mqtt_rig.hpp"

using namespace errsep;
using namespace std::chrono_literals;

namespace {

std::map<std::string, std::string> snapshot(const std::filesystem::path& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    std::ifstream in(e.path(), std::ios::binary);
    std::ostringstream ss;
    ss << in.rdbuf();
    out[e.path().filename().string()] = ss.str();
  }
  return out;
}

/// Every scan of a results store (complete or ended by a device fault), by stem.
std::set<std::string> scan_stems(const std::filesystem::path& results) {
  std::set<std::string> out;
  for (const auto& e : std::filesystem::directory_iterator(results))
    if (const auto f = io::parse_store_name(e.path())) out.insert(f->stem);
  return out;
}

/// One scan through the register map's start coil; waits until it is written (last scan id) and
/// the daemon is idle again.  A scan that a device fault ends (a starved simulator on a loaded
/// machine) is a scan too: its raw data and summary must travel like any other.
void scan_once(test::DaemonRig& rig, long expected_id) {
  const auto r0 = rig.wait_regs([](const std::vector<long>& r) { return r[0] == 1; }, 20s);
  REQUIRE(r0.size() == test::kRegisterCount);
  REQUIRE(test::mbpoll_write_coil(rig.modbus_port, 0, 1) == 0);
  const auto r = rig.wait_regs(
      [&](const std::vector<long>& x) {
        return x[test::reg_last_scan_id] == expected_id && x[test::reg_state] == 1;
      },
      30s);
  INFO(rig.logs());
  REQUIRE(r.size() == test::kRegisterCount);
  REQUIRE(r[test::reg_last_scan_id] == expected_id);
  REQUIRE((r[test::reg_last_outcome] == 1 || r[test::reg_last_outcome] == 3));
}

}  // namespace

TEST_CASE(
    "faults: broker stopped and restarted, a service SIGKILLed with a non-empty queue: every scan "
    "delivered, local results untouched") {
  if (const auto why = test::mqtt_tools_missing(); !why.empty()) {
    std::cout << "SKIPPED: " << why << "\n";
    return;
  }
  const std::vector<std::string> names = {"m0", "m1"};
  test::MqttBroker broker({names, true, false, true});
  broker.start();
  // A persistent session: what arrives at the broker while this subscriber is cut off by the
  // broker's restart is kept for it (QoS 1).
  test::MqttSubscriber sub(broker, "viewer", "errsep/#", "faults-subscriber");

  std::vector<std::unique_ptr<test::DaemonRig>> rigs;
  for (const auto& n : names) {
    auto rig = std::make_unique<test::DaemonRig>();
    test::use_mqtt_config(*rig, test::mqtt_table(broker, n, false));
    rig->devsim.start(rig->config, rig->tmp / "devsim.log");
    rig->start_daemon();
    rigs.push_back(std::move(rig));
  }
  auto queue_dir = [&](std::size_t i) { return rigs[i]->tmp / "mqtt-queue"; };
  auto logs = [&] {
    std::string s = "broker:\n" + broker.log().substr(0, 3000);
    for (const auto& r : rigs)
      s += "\n--- " + r->logs().substr(0, 4000);
    return s;
  };
  INFO(logs());
  for (auto& r : rigs)
    REQUIRE(r->notify->wait_for("READY=1", 30s));

  // 1. Broker up: scan 1 on each.
  for (auto& r : rigs)
    scan_once(*r, 1);
  // 2. Broker stopped: scans 2 and 3 are queued on disk.
  broker.stop();
  for (auto& r : rigs) {
    scan_once(*r, 2);
    scan_once(*r, 3);
  }
  const std::size_t queued_m1 = io::MessageQueue(queue_dir(1)).size();
  CHECK(queued_m1 >= 2);  // the summaries of scans 2 and 3 at least
  CHECK(io::MessageQueue(queue_dir(0)).size() >= 2);
  // 3. SIGKILL of m1 with its queue non-empty, then started again (broker still down).
  rigs[1]->daemon->signal(SIGKILL);
  rigs[1]->daemon->wait(5s);
  const auto before_m0 = snapshot(rigs[0]->results);
  const auto before_m1 = snapshot(rigs[1]->results);
  CHECK(io::MessageQueue(queue_dir(1)).size() == queued_m1);  // the kill lost nothing queued
  rigs[1]->start_daemon();
  REQUIRE(rigs[1]->notify->wait_for("READY=1", 30s));
  for (auto& r : rigs)
    scan_once(*r, 4);
  // 4. Broker back (same port): the queues drain; scan 5 goes straight through.
  broker.start();
  for (auto& r : rigs)
    scan_once(*r, 5);

  auto all_in = [&](const std::vector<test::MqttMessage>& ms) {
    std::set<std::string> got;
    for (const auto& m : ms)
      got.insert(m.topic);
    for (std::size_t i = 0; i < names.size(); ++i)
      for (const auto& s : scan_stems(rigs[i]->results))
        if (!got.count("errsep/" + names[i] + "/scan/" + s)) return false;
    return true;
  };
  const auto msgs = sub.wait(all_in, 60s);
  INFO(sub.log());
  CHECK(all_in(msgs));
  for (std::size_t i = 0; i < names.size(); ++i) {
    INFO("machine " << names[i]);
    CHECK(scan_stems(rigs[i]->results).size() == 5);
  }

  // At least once, nothing else: every scan message names a scan of its machine's store, its
  // payload says the same scan id, and a duplicate carries the same summary.
  std::map<std::string, std::set<std::string>> payloads;
  std::size_t scan_msgs = 0;
  for (const auto& m : msgs) {
    const auto p = m.topic.find("/scan/");
    if (p == std::string::npos) continue;
    ++scan_msgs;
    const std::string machine = m.topic.substr(7, p - 7), id = m.topic.substr(p + 6);
    const std::size_t i = machine == "m0" ? 0 : 1;
    CHECK(scan_stems(rigs[i]->results).count(id) == 1);
    CHECK(test::json_field(m.payload, "scan_id") == id);
    payloads[m.topic].insert(m.payload);
  }
  for (const auto& [topic, ps] : payloads) {
    INFO(topic);
    CHECK(ps.size() == 1);
  }
  std::cout << "faults: " << scan_msgs << " scan messages for " << payloads.size() << " scans ("
            << scan_msgs - payloads.size() << " duplicates); m1 SIGKILLed with " << queued_m1
            << " messages queued\n";
  const std::string invalid = test::validate_payloads(msgs);
  INFO(invalid);
  CHECK(invalid.empty());
  // The queues drained (every message acknowledged and removed).
  for (std::size_t i = 0; i < names.size(); ++i) {
    const auto until = std::chrono::steady_clock::now() + 20s;
    while (io::MessageQueue(queue_dir(i)).size() > 0 && std::chrono::steady_clock::now() < until)
      std::this_thread::sleep_for(50ms);
    CHECK(io::MessageQueue(queue_dir(i)).size() == 0);
  }
  // Local results untouched: every file present after the kill is still there, unchanged.
  const auto after_m0 = snapshot(rigs[0]->results);
  const auto after_m1 = snapshot(rigs[1]->results);
  for (const auto& [name, content] : before_m0) {
    INFO(name);
    REQUIRE(after_m0.count(name));
    CHECK(after_m0.at(name) == content);
  }
  for (const auto& [name, content] : before_m1) {
    INFO(name);
    REQUIRE(after_m1.count(name));
    CHECK(after_m1.at(name) == content);
  }
}

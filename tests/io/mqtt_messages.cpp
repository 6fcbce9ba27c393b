// The MQTT side's files and payloads without a broker: the [mqtt] table of the machine config
// (defaults, every mistake named with file:line:key), cmd/scan parsing (malformed payloads
// refused with a reason), the scan summary read back from a results store, the alarms a scan
// raises (tolerance exceeded, proven only beyond U), and every payload against the schema.
#include "errsep/io/mqtt_messages.hpp"

#include <catch2/catch.hpp>
#include <fstream>
#include <sstream>

#include "errsep/io/csv.hpp"
#include "errsep/io/machine_config.hpp"
#include "errsep/io/results_store.hpp"
#include "support/mqtt_rig.hpp"
#include "support/support.hpp"

using namespace errsep;

namespace {

std::string base_config() {
  std::ifstream in(test::source_dir() / "tests/apps/daemon_machine.toml");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string error_of(const std::string& text) {
  try {
    io::parse_machine_config(text, "t.toml");
  } catch (const io::ConfigError& e) {
    return e.what();
  }
  FAIL("no ConfigError for:\n" << text);
  return {};
}

/// A results store with one scan: raw + result with the daemon's metadata.
std::string stored_scan(const std::filesystem::path& dir, double mz_um, double U_um,
                        const std::string& outcome = "complete") {
  io::ResultsStoreOptions o;
  o.dir = dir;
  o.min_free_bytes = 0;
  io::ResultsStore store(o);
  const std::string stem = io::ResultsStore::stem(std::chrono::system_clock::now(), 42);
  io::CsvTable t;
  for (const auto& [k, v] :
       std::vector<std::pair<std::string, std::string>>{{"scan_id", "42"},
                                                        {"trigger", "schedule"},
                                                        {"started_utc", "2026-11-25T10:00:00Z"},
                                                        {"ended_utc", "2026-11-25T10:00:05Z"},
                                                        {"outcome", outcome},
                                                        {"points_measured", "52/52"}})
    t.set_meta(k, v);
  io::CsvTable raw = t;
  raw.add_column("x_mm", {0, 5});
  store.write(stem, "raw", io::format_csv(raw));
  t.set_meta("straightness_minimum_zone_um", std::to_string(mz_um));
  t.set_meta("straightness_minimum_zone_U_um", std::to_string(U_um));
  t.set_meta("straightness_least_squares_um", std::to_string(mz_um * 1.1));
  t.set_meta("straightness_least_squares_U_um", std::to_string(U_um));
  t.set_meta("lambda", "0");
  t.set_meta("sigma_hat_um", "0.05");
  t.set_meta("solver", "lambda 0 (no corner)");
  t.add_column("x_mm", {0, 5});
  t.add_column("S_um", {0, 1});
  store.write(stem, "result", io::format_csv(t));
  return stem;
}

}  // namespace

TEST_CASE("mqtt table of the machine config: defaults and mistakes named with file, line and key") {
  const std::string cfg = base_config();
  const auto c = io::parse_machine_config(cfg + "\n[mqtt]\nmachine = \"mill-7\"\n", "t.toml");
  REQUIRE(c.mqtt);
  CHECK(c.mqtt->host == "127.0.0.1");
  CHECK(c.mqtt->port == 1883);
  CHECK(c.mqtt->qos == 1);
  CHECK_FALSE(c.mqtt->commands);
  CHECK(c.mqtt->effective_client_id() == "errsep-mill-7");
  CHECK(c.mqtt->topic_root() == "errsep/mill-7");
  CHECK_FALSE(io::parse_machine_config(cfg, "t.toml").mqtt);

  CHECK_THAT(error_of(cfg + "\n[mqtt]\nhost = \"b\"\n"),
             Catch::Contains("t.toml:") && Catch::Contains("mqtt: missing required key 'machine'"));
  CHECK_THAT(error_of(cfg + "\n[mqtt]\nmachine = \"a/b\"\n"), Catch::Contains("mqtt.machine"));
  CHECK_THAT(error_of(cfg + "\n[mqtt]\nmachine = \"m#\"\n"), Catch::Contains("mqtt.machine"));
  CHECK_THAT(error_of(cfg + "\n[mqtt]\nmachine = \"m\"\nqos = 0\n"),
             Catch::Contains("mqtt.qos") && Catch::Contains("out of range"));
  CHECK_THAT(error_of(cfg + "\n[mqtt]\nmachine = \"m\"\ntopic_prefix = \"plant/\"\n"),
             Catch::Contains("mqtt.topic_prefix"));
  CHECK_THAT(error_of(cfg + "\n[mqtt]\nmachine = \"m\"\npassword_file = \"p\"\n"),
             Catch::Contains("a password needs a username"));
  CHECK_THAT(error_of(cfg + "\n[mqtt]\nmachine = \"m\"\ntls_cert_file = \"c\"\n"),
             Catch::Contains("go together"));
  CHECK_THAT(error_of(cfg + "\n[mqtt]\nmachine = \"m\"\nbroker = \"x\"\n"),
             Catch::Contains("mqtt.broker: unknown key"));
}

TEST_CASE("cmd/scan payloads: only a request_id - the rest refused with a reason") {
  std::string why;
  const auto ok = io::parse_scan_command(R"({"request_id":"abc-1"})", &why);
  REQUIRE(ok);
  CHECK(ok->request_id == "abc-1");
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"", "not JSON"},
      {"scan", "not JSON"},
      {"[1]", "not a JSON object"},
      {"{}", "missing key 'request_id'"},
      {R"({"request_id":1})", "must be a string"},
      {R"({"request_id":""})", "1 to 64"},
      {R"({"request_id":"a","n":2})", "unknown key 'n'"},
      {"{\"request_id\":\"" + std::string(65, 'x') + "\"}", "1 to 64"},
      {R"({"request_id":"a\u0001"})", "control character"},
      {std::string(2000, ' '), "longer than 1024"}};
  for (const auto& [payload, reason] : bad) {
    INFO(payload);
    why.clear();
    CHECK_FALSE(io::parse_scan_command(payload, &why));
    CHECK_THAT(why, Catch::Contains(reason));
  }
}

TEST_CASE("scan summary from the results store - alarms - every payload valid against the schema") {
  test::TempDir tmp;
  const std::string stem = stored_scan(tmp / "results", 3.2, 0.4);
  const io::ScanSummary s = io::summarize_stored_scan(tmp / "results", stem, "mill-7");
  CHECK(s.scan_id == stem);
  CHECK(s.scan_number == 42);
  CHECK(s.trigger == "schedule");
  CHECK(s.outcome == "complete");
  REQUIRE(s.straightness_minimum_zone_um);
  CHECK(*s.straightness_minimum_zone_um == Approx(3.2));
  CHECK(*s.straightness_minimum_zone_U_um == Approx(0.4));
  CHECK(*s.sigma_hat_um == Approx(0.05));
  CHECK(s.files == std::vector<std::string>{stem + ".raw.csv", stem + ".result.csv"});
  CHECK_THROWS_WITH(io::summarize_stored_scan(tmp / "results", "nope", "m"),
                    Catch::Contains("no file of scan nope"));

  // Tolerance: 3.2 > 3.0 but 3.2 - 0.4 < 3.0: an alarm, not proven; above 3.6 proven.
  CHECK(io::alarms_for(s, 0.0).empty());
  CHECK(io::alarms_for(s, 3.5).empty());
  auto a = io::alarms_for(s, 3.0);
  REQUIRE(a.size() == 1);
  CHECK(a[0].kind == "straightness_tolerance");
  CHECK(*a[0].proven == false);
  a = io::alarms_for(s, 2.5);
  REQUIRE(a.size() == 1);
  CHECK(*a[0].proven == true);
  io::ScanSummary f = s;
  f.outcome = "device_fault";
  f.outcome_reason = "stage slide: timeout";
  CHECK(io::alarms_for(f, 0.0).size() == 1);
  CHECK(io::alarms_for(f, 0.0)[0].kind == "device_fault");

  if (const auto why = test::mqtt_tools_missing(); !why.empty()) {
    WARN("schema check not run: " << why);
    return;
  }
  std::vector<test::MqttMessage> ms;
  ms.push_back({"", false, io::to_json(s)});
  ms.push_back({"", false, io::to_json(io::alarms_for(s, 3.0)[0])});
  ms.push_back({"", false, io::to_json(io::alarms_for(f, 0.0)[0])});
  ms.push_back(
      {"", false, io::to_json(io::StatusMessage{"mill-7", true, "idle", "", stem, 2, ""})});
  ms.push_back(
      {"", false, io::to_json(io::StatusMessage{"mill-7", false, "offline", "", "", 0, ""})});
  ms.push_back({"", false, io::to_json(io::CommandReply{"mill-7", "r1", true, "", ""})});
  ms.push_back({"", false, io::to_json(io::CommandReply{"mill-7", "", false, "malformed", ""})});
  CHECK(test::validate_payloads(ms).empty());
  // The schema refuses what it should: a status online but "offline", a refusal without reason,
  // a scan without its scan id.
  std::vector<test::MqttMessage> wrong = {
      {"", false, io::to_json(io::StatusMessage{"mill-7", true, "offline", "", "", 0, ""})}};
  CHECK_FALSE(test::validate_payloads(wrong).empty());
  wrong = {{"", false, io::to_json(io::CommandReply{"mill-7", "r", false, "", ""})}};
  CHECK_FALSE(test::validate_payloads(wrong).empty());
  io::ScanSummary no_id = s;
  no_id.scan_id.clear();
  wrong = {{"", false, io::to_json(no_id)}};
  CHECK_FALSE(test::validate_payloads(wrong).empty());
}

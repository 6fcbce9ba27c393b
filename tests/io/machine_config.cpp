// The machine config reader: the shipped configs parse to what they say, and every kind of
// mistake gives "file:line: key: problem" naming the right key and line.
#include <algorithm>
#include <catch2/catch.hpp>
#include <fstream>
#include <string>

#include "errsep/io/machine_config.hpp"
#include "support/support.hpp"

using namespace errsep::io;

namespace {

const char* kMinimal = R"(
[[bus]]
name = "b"
kind = "tcp"
host = "127.0.0.1"
port = 1502

[[sensor]]
name = "s"
bus = "b"
register = { address = 4, type = "int32", word_order = "little", scale = 0.001 }

[[stage]]
name = "x"
role = "slide"
bus = "m"
target_position = { address = 100 }
actual_position = { address = 100 }
status = { address = 104 }
stop_coil = { address = 0 }

[[bus]]
name = "m"
kind = "tcp"
host = "127.0.0.1"
port = 1503
)";

// Parses `text` expecting a ConfigError; returns its message.
std::string error_of(const std::string& text) {
  try {
    parse_machine_config(text, "t.toml");
  } catch (const ConfigError& e) {
    return e.what();
  }
  FAIL("no ConfigError for:\n" << text);
  return {};
}

}  // namespace

TEST_CASE("a minimal config parses with the documented defaults") {
  const MachineConfig c = parse_machine_config(kMinimal, "t.toml");
  REQUIRE(c.buses.size() == 2);
  CHECK(c.buses[0].kind == BusKind::tcp);
  CHECK(c.buses[0].port == 1502);
  REQUIRE(c.sensors.size() == 1);
  const RegisterSpec& r = c.sensors[0].reg;
  CHECK(r.address == 4);
  CHECK(r.kind == RegisterKind::input);  // default for a sensor
  CHECK(r.type == RegisterType::int32);
  CHECK(r.word_order == WordOrder::little);
  CHECK(r.scale == 0.001);
  REQUIRE(c.stages.size() == 1);
  CHECK(c.stages[0].target_position.kind == RegisterKind::holding);
  CHECK(c.stages[0].actual_position.kind == RegisterKind::input);
  CHECK(c.stages[0].status.type == RegisterType::uint16);
  CHECK(c.stages[0].stop_coil.kind == RegisterKind::coil);
  CHECK_FALSE(c.gpio.has_value());
  CHECK(c.sample_rate_hz(c.buses[0]) == c.sampler.rate_hz);
}

TEST_CASE("config/simulator.toml parses and is self-consistent") {
  const auto path = errsep::test::source_dir() / "config" / "simulator.toml";
  const MachineConfig c = load_machine_config(path);
  CHECK(c.simulator.embedded);
  CHECK(c.simulator.host == "127.0.0.1");
  CHECK(c.simulator.port == 0);
  CHECK(c.buses.size() == 2);
  for (const auto& b : c.buses)
    CHECK(b.port == 0);  // filled in from the simulator
  CHECK(c.scan.method == ScanMethod::four_sensor);
  CHECK(c.scan.single_sensor);
  CHECK(c.scan.sensors == std::vector<std::string>{"sensor1"});
  CHECK(c.scan.geometry.N == 69);
  CHECK(c.scan.geometry.positions() == 62);
  CHECK(c.scan.averages == 100);
  CHECK(c.simulator.e_um[3] == 0.07);
  REQUIRE(c.find_stage("reference_piece"));
  CHECK(c.find_stage("reference_piece")->target_position.type == RegisterType::int32);
  CHECK(c.find_stage("reference_piece")->target_position.word_order == WordOrder::little);
  CHECK(c.simulator.m_um.harmonics.size() == 1);
  MachineConfig copy = c;
  CHECK(apply_simulator_port(copy, 40123) == 2);
  CHECK(copy.buses[1].port == 40123);
}

TEST_CASE("config/machine-example.toml parses (RTU, TCP drive, GPIO)") {
  const auto path = errsep::test::source_dir() / "config" / "machine-example.toml";
  const MachineConfig c = load_machine_config(path);
  const BusConfig* rs = c.find_bus("rs485");
  REQUIRE(rs);
  CHECK(rs->kind == BusKind::rtu);
  CHECK(rs->device == "/dev/ttyUSB0");
  CHECK(rs->parity == Parity::even);
  CHECK(c.sample_rate_hz(*rs) == 50.0);
  REQUIRE(c.gpio.has_value());
  CHECK(c.gpio->chip == "gpiochip0");
  CHECK(c.gpio->start_line == 17);
  CHECK_FALSE(c.scan.single_sensor);
  CHECK(c.scan.sensors.size() == 4);
  CHECK(c.find_sensor("s1")->reg.unit_id == 3);  // device unit id passed to the register
  CHECK(c.find_stage("x")->fault_bit == 3);
  CHECK_FALSE(c.simulator.embedded);
}

TEST_CASE("mistakes name the file, the line and the key") {
  // Unknown (misspelt) key, on line 11 of the text.
  std::string m;
  std::string t = kMinimal;
  t.replace(t.find("register ="), 8, "regster");
  m = error_of(t);
  CHECK(m.find("t.toml:11: sensor[0].regster: unknown key") == 0);

  // Wrong type.
  t = kMinimal;
  t.replace(t.find("port = 1502"), 11, "port = \"1502\"");
  m = error_of(t);
  CHECK(m.find("t.toml:6: bus[0].port: expected an integer") == 0);

  // Missing required key: reported at the table's line.
  t = kMinimal;
  t.replace(t.find("bus = \"b\"\nregister"), 9, "");
  m = error_of(t);
  CHECK(m.find("t.toml:") == 0);
  CHECK(m.find("sensor[0]: missing required key 'bus'") != std::string::npos);

  // Dangling reference.
  t = kMinimal;
  t.replace(t.find("bus = \"b\"\nregister"), 9, "bus = \"c\"");
  CHECK(error_of(t).find("sensor[0].bus: no [[bus]] named 'c'") != std::string::npos);

  // Bad enum value, inside an inline table.
  t = kMinimal;
  t.replace(t.find("\"int32\""), 7, "\"float64\"");
  m = error_of(t);
  CHECK(m.find("t.toml:11: sensor[0].register.type: 'float64' is not one of") == 0);

  // Out-of-range values.
  CHECK(error_of(std::string(kMinimal) + "[sampler]\nfifo_priority = 120\n")
            .find("sampler.fifo_priority: 120 is out of range 1..99") != std::string::npos);
  CHECK(error_of(std::string(kMinimal) + "[[sensor]]\nname = \"r\"\nbus = \"b\"\n"
                                         "register = { address = 8 }\nrange_min_um = 5\n"
                                         "range_max_um = -5\n")
            .find("sensor[1].range_max_um: must be greater than range_min_um") !=
        std::string::npos);

  // A stage on a bus that carries sensors: the sampling thread owns a sensor bus's connection.
  t = kMinimal;
  t.replace(t.find("bus = \"m\""), 9, "bus = \"b\"");
  m = error_of(t);
  CHECK(m.find("t.toml:") == 0);
  CHECK(m.find("stage[0].bus: bus 'b' also carries sensor 's'") != std::string::npos);

  // TOML syntax error: line of the error.
  m = error_of("[[bus]]\nname = \"b\"\nport = = 3\n");
  CHECK(m.find("t.toml:3: TOML syntax error") == 0);
}

TEST_CASE("cross-field rules of scan and simulator") {
  std::string m = error_of(std::string(kMinimal) +
                           "[scan]\nsingle_sensor = false\n"
                           "sensors = [\"s\"]\nslide_stage = \"x\"\n");
  CHECK(m.find("scan.sensors: has 1 names; single_sensor = false needs exactly 4") !=
        std::string::npos);
  m = error_of(std::string(kMinimal) +
               "[scan]\nsensors = [\"s\"]\nslide_stage = \"x\"\n"
               "sensor_stage = \"x\"\n");
  CHECK(m.find("scan.sensor_stage: stage 'x' has role slide, expected sensor_stage") !=
        std::string::npos);
  m = error_of(std::string(kMinimal) + "[scan]\nN = 8\nsensors = [\"s\"]\n");
  CHECK(m.find("scan.N: N = 8 must exceed s2 + s3 + s4 + 1 = 8") != std::string::npos);
  m = error_of(std::string(kMinimal) + "[simulator]\nhost = \"0.0.0.0\"\n");
  CHECK(m.find("simulator.host: '0.0.0.0': the simulator binds to loopback only") !=
        std::string::npos);
  std::string t = kMinimal;
  t.replace(t.find("port = 1502"), 11, "port = 0");
  CHECK(error_of(t).find("t.toml:6: bus[0].port: port 0 is only allowed with [simulator] "
                         "embedded = true") == 0);
  CHECK_NOTHROW(parse_machine_config(t + "[simulator]\nembedded = true\n", "t.toml"));
  m = error_of(std::string(kMinimal) + "[simulator]\ne_um = [1, 2]\n");
  CHECK(m.find("simulator.e_um: expected 4 numbers") != std::string::npos);
}

TEST_CASE("file errors carry the path") {
  errsep::test::TempDir dir;
  const auto missing = dir / "nope.toml";
  try {
    load_machine_config(missing);
    FAIL("no error for a missing file");
  } catch (const ConfigError& e) {
    CHECK(std::string(e.what()).find(missing.string() + ": cannot open") == 0);
  }
  const auto bad = dir / "bad.toml";
  std::ofstream(bad) << "[[bus]]\nname = \"b\"\nkind = \"can\"\n";
  try {
    load_machine_config(bad);
    FAIL("no error for a bad bus kind");
  } catch (const ConfigError& e) {
    CHECK(std::string(e.what()) == bad.string() + ":3: bus[0].kind: 'can' is not one of tcp, rtu");
    CHECK(e.line() == 3);
    CHECK(e.key() == "bus[0].kind");
  }
}

TEST_CASE("warnings for settings that are allowed but probably not meant") {
  MachineConfig c = parse_machine_config(kMinimal, "t.toml");
  c.buses[0].response_timeout_ms = 50;
  c.buses[0].retries = 1;
  c.sampler.rate_hz = 1000.0;
  auto w = config_warnings(c);
  REQUIRE(w.size() == 1);
  CHECK(w[0].find("bus 'b': (1 + retries) x response_timeout_ms = 100 ms exceeds the sample "
                  "period") == 0);
  c.sampler.rate_hz = 5.0;  // 200 ms period: fine
  CHECK(config_warnings(c).empty());
  const MachineConfig ex =
      load_machine_config(errsep::test::source_dir() / "config" / "machine-example.toml");
  for (const auto& m : config_warnings(ex))
    INFO(m);
  // 4 sensors × 50 Hz = 200/s fits the RTU line; (1 + 1) × 20 ms = 40 ms > 20 ms period.
  const auto wex = config_warnings(ex);
  REQUIRE(wex.size() == 1);
  CHECK(wex[0].find("bus 'rs485'") == 0);
}

TEST_CASE("[axes] and [compensation]: machine coordinates and each format's own parameters") {
  // Defaults: X moves, Y read, towards +, reading grows towards +Y; every format.
  const MachineConfig d = parse_machine_config(kMinimal, "t.toml");
  CHECK(d.axes.input_axis == 'X');
  CHECK(d.axes.output_axis == 'Y');
  CHECK(d.axes.scan_direction == 1);
  CHECK(d.axes.reading_sign == 1);
  CHECK(d.compensation.tables.formats.size() == all_compensation_formats().size());
  CHECK(d.compensation.profile.remove_line == errsep::core::ReferenceLine::end_points);

  const std::string t = std::string(kMinimal) + R"(
[scan]
method = "displacement"
slide_start_mm = 250.0
slide_stage = "x"
workpiece_sensor = "s"
reference_sensor = "r"
reference_stage = "p"
[[sensor]]
name = "r"
bus = "b"
register = { address = 8 }
[[stage]]
name = "p"
role = "reference_piece"
bus = "m"
target_position = { address = 120 }
actual_position = { address = 120 }
status = { address = 124 }
stop_coil = { address = 2 }
[axes]
input = "y"
output = "Z"
scan_direction = -1
reading_sign = -1
[compensation]
formats = ["heidenhain_com", "sinumerik_cec"]
remove_line = "none"
[compensation.sinumerik_cec]
input_axis = "Y1"
output_axis = "Z1"
max_points = 120
[compensation.heidenhain_com]
table_dir = "PLC:\\comp\\"
)";
  const MachineConfig c = parse_machine_config(t, "t.toml");
  CHECK(c.axes.input_axis == 'Y');
  CHECK(c.axes.output_axis == 'Z');
  CHECK(c.axes.scan_direction == -1);
  CHECK(c.axes.reading_sign == -1);
  CHECK(c.axes.slide_start_mm == 250);
  CHECK(c.axes.symbol() == "EZY");
  REQUIRE(c.compensation.tables.formats.size() == 2);
  CHECK(c.compensation.tables.formats[0] == CompensationFormat::heidenhain_com);
  CHECK_FALSE(c.compensation.profile.remove_line.has_value());
  const auto& sp = c.compensation.tables.parameters.at(CompensationFormat::sinumerik_cec);
  CHECK(sp.at("input_axis") == "Y1");
  CHECK(sp.at("max_points") == "120");
  CHECK(c.compensation.tables.parameters.at(CompensationFormat::heidenhain_com).at("table_dir") ==
        "PLC:\\comp\\");

  // Mistakes name file, line and key; the format judges its own parameters.
  const std::string base = std::string(kMinimal);
  CHECK(error_of(base + "[axes]\ninput = \"X\"\noutput = \"X\"\n")
            .find("axes.output: equals input") != std::string::npos);
  CHECK(error_of(base + "[axes]\ninput = \"W\"\n").find("axes.input: 'W' is not X, Y or Z") !=
        std::string::npos);
  CHECK(error_of(base + "[axes]\nscan_direction = 0\n").find("axes.scan_direction: must be 1") !=
        std::string::npos);
  CHECK(error_of(base + "[compensation]\nformats = [\"fanuc\"]\n")
            .find("compensation.formats: 'fanuc' is not one of sinumerik_cec") !=
        std::string::npos);
  const std::string m = error_of(
      base + "[compensation]\n[compensation.linuxcnc_hal]\nscale_mm = 1e-6\npoints = 500\n");
  CHECK(m.find("t.toml:30: compensation.linuxcnc_hal.points: 500 is out of range") == 0);
  CHECK(error_of(base + "[compensation.beckhoff_crosscomp]\nmaster = 3\n")
            .find("compensation.beckhoff_crosscomp.master: unknown parameter (known: axis,") !=
        std::string::npos);
  CHECK(error_of(base + "[compensation]\nstep = 5\n").find("compensation.step: unknown key") !=
        std::string::npos);
}

namespace {
// Line number of the first line of `tail` appended to kMinimal.
int line_after_minimal() {
  const std::string t = kMinimal;
  return static_cast<int>(std::count(t.begin(), t.end(), '\n')) + 1;
}
}  // namespace

TEST_CASE("[separation]: one vocabulary with core, defaults, and file:line: key errors") {
  using errsep::core::CurvatureGauge;
  using errsep::core::LambdaRule;
  // Without the table: the defaults errsep-scan used before it existed (core::options_for_gauge).
  const MachineConfig d = parse_machine_config(kMinimal, "t.toml");
  CHECK(d.separation.gauge == CurvatureGauge::reference_without_curvature);
  CHECK(!d.separation.lambda_rule);
  CHECK(d.separation.options().rule ==
        errsep::core::options_for_gauge(CurvatureGauge::reference_without_curvature).rule);
  CHECK(d.separation.is_valid(nullptr));

  const MachineConfig c =
      parse_machine_config(std::string(kMinimal) +
                               "[separation]\ngauge = \"sensor_stage\"\nlambda_rule = \"lcurve\"\n"
                               "lambda_min = 1e-4\nlambda_max = 10.0\nthreads = 2\n",
                           "t.toml");
  CHECK(c.separation.gauge == CurvatureGauge::sensor_stage_without_curvature);
  REQUIRE(c.separation.lambda_rule);
  CHECK(*c.separation.lambda_rule == LambdaRule::lcurve);
  const auto o = c.separation.options();
  CHECK(o.gauge == CurvatureGauge::sensor_stage_without_curvature);
  CHECK(o.rule == LambdaRule::lcurve);
  CHECK(o.lcurve.lambda_min == 1e-4);
  CHECK(o.lcurve.lambda_max == 10.0);
  CHECK(o.lcurve.threads == 2);
  CHECK(o.search.threads == 2);
  // Every name core knows is accepted, and is the one core writes back.
  for (const auto& g : errsep::core::curvature_gauge_names()) {
    const auto p = parse_machine_config(
        std::string(kMinimal) + "[separation]\ngauge = \"" + g + "\"\n", "t.toml");
    CHECK(errsep::core::to_string(p.separation.gauge) == g);
  }
  for (const auto& r : errsep::core::lambda_rule_names()) {
    const auto p =
        parse_machine_config(std::string(kMinimal) + "[separation]\nlambda_rule = \"" + r + "\"" +
                                 (r == "fixed" ? "\nfixed_lambda = 0.5" : "") + "\n",
                             "t.toml");
    CHECK(errsep::core::to_string(*p.separation.lambda_rule) == r);
  }

  struct Bad {
    const char* body;
    int line;  // of the body, from 1
    const char* where;
    const char* problem;
  };
  for (const Bad& b :
       {Bad{"gauge = \"flat\"\n", 1, "separation.gauge", "'flat' is not one of \"reference\""},
        Bad{"lambda_rule = \"best\"\n", 1, "separation.lambda_rule", "is not one of \"reml\""},
        Bad{"threads = 0\n", 1, "separation.threads", ""},
        Bad{"lambda_min = 2.0\nlambda_max = 1.0\n", 2, "separation.lambda_max",
            "must be above lambda_min"},
        Bad{"lambda_rule = \"fixed\"\n", 1, "separation.fixed_lambda", "needs fixed_lambda > 0"},
        Bad{"guage = \"reference\"\n", 1, "separation.guage", "unknown key"}}) {
    const std::string m = error_of(std::string(kMinimal) + "[separation]\n" + b.body);
    INFO(m);
    const std::string at = "t.toml:" + std::to_string(line_after_minimal() + b.line) + ": ";
    if (std::string(b.where) != "separation.fixed_lambda")  // no such key: the table's line
      CHECK(m.find(at + b.where) == 0);
    CHECK(m.find(b.where) != std::string::npos);
    CHECK(m.find(b.problem) != std::string::npos);
  }
}

TEST_CASE("[report]: particulars, tolerance and PDF switch") {
  const MachineConfig d = parse_machine_config(kMinimal, "t.toml");
  CHECK(d.report.pdf);
  CHECK(!d.report.straightness_tolerance_um);
  const MachineConfig c = parse_machine_config(
      std::string(kMinimal) +
          "[report]\nmachine = \"M1\"\noperator = \"J. Doe\"\ninstrument = \"rig 2\"\n"
          "temperature_c = 20.5\nstraightness_tolerance_um = 8\npdf = false\n",
      "t.toml");
  CHECK(c.report.machine == "M1");
  CHECK(c.report.operator_name == "J. Doe");
  CHECK(c.report.instrument == "rig 2");
  CHECK(*c.report.temperature_c == 20.5);
  CHECK(*c.report.straightness_tolerance_um == 8.0);
  CHECK(!c.report.pdf);
  const std::string m =
      error_of(std::string(kMinimal) + "[report]\nstraightness_tolerance_um = -1\n");
  CHECK(m.find("t.toml:" + std::to_string(line_after_minimal() + 1) +
               ": report.straightness_tolerance_um: must be > 0") == 0);
}

// Issue 16 item 2: [scan] plan names the order of the traverses (core/scan_sequence.hpp).
TEST_CASE("[scan] plan: single by default, the scan sequence's names, errors with file:line") {
  const auto path = errsep::test::source_dir() / "config" / "simulator.toml";
  const std::string text = errsep::test::read_file(path);
  CHECK(parse_machine_config(text, "s.toml").scan.plan == errsep::core::ScanSequenceKind::single);
  auto with = [&](const std::string& plan) {
    std::string t = text;
    t.replace(t.find("[scan]\n"), 7, "[scan]\nplan = \"" + plan + "\"\n");
    return t;
  };
  CHECK(parse_machine_config(with("reversed"), "s.toml").scan.plan ==
        errsep::core::ScanSequenceKind::reversed);
  CHECK(parse_machine_config(with("closing"), "s.toml").scan.plan ==
        errsep::core::ScanSequenceKind::closing_pass);
  CHECK(parse_machine_config(with("interleaved"), "s.toml").scan.plan ==
        errsep::core::ScanSequenceKind::interleaved);
  const std::string m = error_of(with("sideways"));
  CHECK(m.find("t.toml:127: scan.plan") == 0);  // the line of the key
  CHECK(m.find("single, closing, reversed, interleaved") != std::string::npos);
}

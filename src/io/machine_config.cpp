#include "errsep/io/machine_config.hpp"

#include <toml++/toml.h>

#include "toml_table_reader.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <set>
#include <sstream>

namespace errsep::io {

double ProfileSpec::eval(double x_mm) const noexcept {
  constexpr double kTwoPi = 6.283185307179586;
  double v = offset + slope_per_mm * x_mm + quadratic_per_mm2 * x_mm * x_mm;
  for (const Harmonic& h : harmonics)
    v += h.amplitude * std::sin(kTwoPi * x_mm / h.period_mm + h.phase_rad);
  return v;
}

const BusConfig* MachineConfig::find_bus(const std::string& name) const {
  for (const auto& b : buses)
    if (b.name == name) return &b;
  return nullptr;
}
const SensorConfig* MachineConfig::find_sensor(const std::string& name) const {
  for (const auto& s : sensors)
    if (s.name == name) return &s;
  return nullptr;
}
const StageConfig* MachineConfig::find_stage(const std::string& name) const {
  for (const auto& s : stages)
    if (s.name == name) return &s;
  return nullptr;
}
double MachineConfig::sample_rate_hz(const BusConfig& bus) const {
  return bus.sample_rate_hz > 0.0 ? bus.sample_rate_hz : sampler.rate_hz;
}

std::vector<std::string> config_warnings(const MachineConfig& cfg) {
  std::vector<std::string> w;
  for (const auto& b : cfg.buses) {
    const double rate = cfg.sample_rate_hz(b);
    const double period_ms = 1000.0 / rate;
    const double worst_ms = (1.0 + b.retries) * b.response_timeout_ms;
    std::size_t n_sensors = 0;
    for (const auto& s : cfg.sensors)
      n_sensors += s.bus == b.name ? 1 : 0;
    if (n_sensors > 0 && worst_ms > period_ms) {
      w.push_back("bus '" + b.name + "': (1 + retries) x response_timeout_ms = " +
                  std::to_string(static_cast<int>(worst_ms)) + " ms exceeds the sample period " +
                  std::to_string(period_ms) + " ms at " + std::to_string(rate) +
                  " Hz: a device that stops answering costs about " +
                  std::to_string(static_cast<long>(worst_ms / period_ms)) +
                  " missed periods per read (they are counted)");
    }
    if (b.kind == BusKind::rtu && n_sensors > 0) {
      // Roughly 100-250 transactions/s per RTU line at 115200 baud (NOTES.md), fewer slower.
      const double capacity = 250.0 * std::min(1.0, b.baud / 115200.0);
      if (rate * static_cast<double>(n_sensors) > capacity)
        w.push_back("bus '" + b.name + "': " + std::to_string(n_sensors) + " sensors at " +
                    std::to_string(rate) + " Hz need " +
                    std::to_string(static_cast<long>(rate * static_cast<double>(n_sensors))) +
                    " transactions/s; an RTU line at " + std::to_string(b.baud) +
                    " baud carries about " + std::to_string(static_cast<long>(capacity)));
    }
  }
  return w;
}

int apply_simulator_port(MachineConfig& cfg, int port) {
  int n = 0;
  for (auto& b : cfg.buses) {
    if (b.kind == BusKind::tcp && b.port == 0) {
      b.port = port;
      ++n;
    }
  }
  return n;
}

const char* to_string(BusKind k) noexcept {
  return k == BusKind::tcp ? "tcp" : "rtu";
}
const char* to_string(StageRole r) noexcept {
  switch (r) {
    case StageRole::slide:
      return "slide";
    case StageRole::sensor_stage:
      return "sensor_stage";
    case StageRole::reference_piece:
      return "reference_piece";
  }
  return "unknown";
}
const char* to_string(ScanMethod m) noexcept {
  switch (m) {
    case ScanMethod::four_sensor:
      return "four_sensor";
    case ScanMethod::displacement:
      return "displacement";
    case ScanMethod::both:
      return "both";
  }
  return "unknown";
}

namespace {

using detail::for_each_table;
using detail::line_of;
using detail::read_string_list;
using Reader = detail::TomlTableReader;

/// A register spec table.  `unit_id` defaults to the device's; `dflt` carries kind and type
/// defaults for this use.
RegisterSpec read_register(const Reader& parent, const std::string& key, int unit_id,
                           RegisterSpec dflt, bool required) {
  const toml::table* t = parent.sub(key);
  if (!t) {
    if (required) parent.require(key);
    dflt.unit_id = unit_id;
    return dflt;
  }
  Reader r(parent.file(), *t, parent.full(key));
  r.only({"unit_id", "address", "kind", "type", "word_order", "scale", "offset"});
  RegisterSpec s = dflt;
  s.unit_id = unit_id;
  r.get_int("unit_id", s.unit_id, 0, 247);
  r.get_int("address", s.address, 0, 65535, true);
  std::string str;
  if (r.has("kind")) {
    r.get("kind", str);
    auto k = parse_register_kind(str);
    r.check("kind", k.has_value(), "'" + str + "' is not one of input, holding, coil");
    s.kind = *k;
  }
  if (r.has("type")) {
    r.get("type", str);
    auto ty = parse_register_type(str);
    r.check("type", ty.has_value(), "'" + str + "' is not one of int16, uint16, int32, float32");
    s.type = *ty;
  }
  if (r.has("word_order")) {
    r.get("word_order", str);
    auto w = parse_word_order(str);
    r.check("word_order", w.has_value(), "'" + str + "' is not one of big, little");
    s.word_order = *w;
  }
  r.get("scale", s.scale);
  r.get("offset", s.offset);
  std::string why;
  if (!s.is_valid(&why)) r.fail("", why);
  return s;
}

ProfileSpec read_profile(const Reader& parent, const std::string& key) {
  ProfileSpec p;
  const toml::table* t = parent.sub(key);
  if (!t) return p;
  Reader r(parent.file(), *t, parent.full(key));
  r.only({"offset", "slope_per_mm", "quadratic_per_mm2", "harmonics"});
  r.get("offset", p.offset);
  r.get("slope_per_mm", p.slope_per_mm);
  r.get("quadratic_per_mm2", p.quadratic_per_mm2);
  if (const toml::node* hn = t->get("harmonics")) {
    const toml::array* arr = hn->as_array();
    if (!arr) r.fail("harmonics", "expected an array of { amplitude, period_mm, phase_rad }");
    for (std::size_t i = 0; i < arr->size(); ++i) {
      const toml::node& e = *arr->get(i);
      const std::string hkey = "harmonics[" + std::to_string(i) + "]";
      if (!e.is_table())
        throw ConfigError(r.file(), line_of(e), r.full(hkey),
                          "expected { amplitude = ..., period_mm = ..., phase_rad = ... }");
      Reader h(r.file(), *e.as_table(), r.full(hkey));
      h.only({"amplitude", "period_mm", "phase_rad"});
      Harmonic hm;
      h.get("amplitude", hm.amplitude, true);
      h.get("period_mm", hm.period_mm, true);
      h.check("period_mm", hm.period_mm != 0.0, "must be non-zero");
      h.get("phase_rad", hm.phase_rad);
      p.harmonics.push_back(hm);
    }
  }
  return p;
}

void read_buses(const std::string& file, const toml::table& root, MachineConfig& c) {
  for_each_table(file, root, "bus", [&](const Reader& r) {
    r.only({"name", "kind", "host", "port", "device", "baud", "parity", "data_bits", "stop_bits",
            "response_timeout_ms", "retries", "sample_rate_hz"});
    BusConfig b;
    r.get("name", b.name, true);
    r.check("name", !b.name.empty(), "must not be empty");
    r.check("name", !c.find_bus(b.name), "duplicate bus name '" + b.name + "'");
    std::string kind = "tcp";
    r.get("kind", kind);
    if (kind == "tcp")
      b.kind = BusKind::tcp;
    else if (kind == "rtu")
      b.kind = BusKind::rtu;
    else
      r.fail("kind", "'" + kind + "' is not one of tcp, rtu");
    if (b.kind == BusKind::tcp) {
      r.get("host", b.host);
      r.check("host", !b.host.empty(), "must not be empty");
      r.get_int("port", b.port, 0, 65535, true);
    } else {
      r.get("device", b.device, true);
      r.check("device", !b.device.empty(), "must name a serial device, e.g. /dev/ttyUSB0");
      r.get_int("baud", b.baud, 300, 4000000);
      std::string parity = "none";
      r.get("parity", parity);
      if (parity == "none")
        b.parity = Parity::none;
      else if (parity == "even")
        b.parity = Parity::even;
      else if (parity == "odd")
        b.parity = Parity::odd;
      else
        r.fail("parity", "'" + parity + "' is not one of none, even, odd");
      r.get_int("data_bits", b.data_bits, 5, 8);
      r.get_int("stop_bits", b.stop_bits, 1, 2);
    }
    r.get_int("response_timeout_ms", b.response_timeout_ms, 1, 60000);
    r.get_int("retries", b.retries, 0, 10);
    r.get("sample_rate_hz", b.sample_rate_hz);
    r.check("sample_rate_hz", b.sample_rate_hz >= 0.0 && b.sample_rate_hz <= 100000.0,
            "must be in 0..100000 (0 = sampler.rate_hz)");
    c.buses.push_back(std::move(b));
  });
}

void read_sensors(const std::string& file, const toml::table& root, MachineConfig& c) {
  for_each_table(file, root, "sensor", [&](const Reader& r) {
    r.only({"name", "bus", "unit_id", "register", "range_min_um", "range_max_um"});
    SensorConfig s;
    r.get("name", s.name, true);
    r.check("name", !s.name.empty(), "must not be empty");
    r.check("name", !c.find_sensor(s.name), "duplicate sensor name '" + s.name + "'");
    r.get("bus", s.bus, true);
    r.check("bus", c.find_bus(s.bus) != nullptr, "no [[bus]] named '" + s.bus + "'");
    int unit = 1;
    r.get_int("unit_id", unit, 0, 247);
    RegisterSpec d;
    d.kind = RegisterKind::input;
    d.type = RegisterType::float32;
    s.reg = read_register(r, "register", unit, d, true);
    if (s.reg.kind == RegisterKind::coil) r.fail("register", "a sensor value cannot be a coil");
    r.get("range_min_um", s.range_min_um);
    r.get("range_max_um", s.range_max_um);
    r.check("range_max_um", s.range_max_um > s.range_min_um, "must be greater than range_min_um");
    c.sensors.push_back(std::move(s));
  });
}

void read_stages(const std::string& file, const toml::table& root, MachineConfig& c) {
  for_each_table(file, root, "stage", [&](const Reader& r) {
    r.only({"name", "role", "bus", "unit_id", "target_position", "actual_position", "status",
            "in_position_bit", "fault_bit", "stop_coil", "fault_code", "speed", "speed_mm_s",
            "position_tolerance_mm", "move_timeout_ms"});
    StageConfig s;
    r.get("name", s.name, true);
    r.check("name", !s.name.empty(), "must not be empty");
    r.check("name", !c.find_stage(s.name), "duplicate stage name '" + s.name + "'");
    std::string role;
    r.get("role", role, true);
    if (role == "slide")
      s.role = StageRole::slide;
    else if (role == "sensor_stage")
      s.role = StageRole::sensor_stage;
    else if (role == "reference_piece")
      s.role = StageRole::reference_piece;
    else
      r.fail("role", "'" + role + "' is not one of slide, sensor_stage, reference_piece");
    r.get("bus", s.bus, true);
    r.check("bus", c.find_bus(s.bus) != nullptr, "no [[bus]] named '" + s.bus + "'");
    // A bus is one libmodbus connection, and a connection serves one thread: the sampling
    // thread owns every bus with sensors on it, the scan worker moves the stages.  Sharing one
    // would interleave their requests on one context.
    for (const auto& sensor : c.sensors)
      r.check("bus", sensor.bus != s.bus,
              "bus '" + s.bus + "' also carries sensor '" + sensor.name +
                  "': stages need a [[bus]] of their own (the sampling thread owns a sensor "
                  "bus; for Modbus TCP, a second [[bus]] to the same host and port)");
    int unit = 1;
    r.get_int("unit_id", unit, 0, 247);
    RegisterSpec pos;
    pos.kind = RegisterKind::holding;
    pos.type = RegisterType::float32;
    s.target_position = read_register(r, "target_position", unit, pos, true);
    r.check("target_position", s.target_position.kind == RegisterKind::holding,
            "must be a holding register (it is written)");
    pos.kind = RegisterKind::input;
    s.actual_position = read_register(r, "actual_position", unit, pos, true);
    r.check("actual_position", s.actual_position.kind != RegisterKind::coil, "cannot be a coil");
    RegisterSpec st;
    st.kind = RegisterKind::input;
    st.type = RegisterType::uint16;
    s.status = read_register(r, "status", unit, st, true);
    r.check("status",
            s.status.kind != RegisterKind::coil &&
                (s.status.type == RegisterType::uint16 || s.status.type == RegisterType::int16),
            "must be a 16-bit (uint16/int16) input or holding register");
    r.get_int("in_position_bit", s.in_position_bit, 0, 15);
    r.get_int("fault_bit", s.fault_bit, 0, 15);
    r.check("fault_bit", s.fault_bit != s.in_position_bit, "must differ from in_position_bit");
    RegisterSpec coil;
    coil.kind = RegisterKind::coil;
    s.stop_coil = read_register(r, "stop_coil", unit, coil, true);
    r.check("stop_coil", s.stop_coil.kind == RegisterKind::coil, "must have kind = \"coil\"");
    if (r.has("fault_code")) {
      s.fault_code = read_register(r, "fault_code", unit, st, true);
      r.check("fault_code", s.fault_code->kind != RegisterKind::coil, "cannot be a coil");
    }
    if (r.has("speed")) {
      s.speed = read_register(r, "speed", unit, pos, true);
      r.check("speed", s.speed->kind == RegisterKind::holding, "must be a holding register");
    }
    r.get("speed_mm_s", s.speed_mm_s);
    r.check("speed_mm_s", s.speed_mm_s >= 0.0, "must be >= 0 (0 = leave the drive's speed)");
    r.get("position_tolerance_mm", s.position_tolerance_mm);
    r.check("position_tolerance_mm", s.position_tolerance_mm > 0.0, "must be > 0");
    r.get_int("move_timeout_ms", s.move_timeout_ms, 1, 3600000);
    c.stages.push_back(std::move(s));
  });
}

void read_gpio(const Reader& root, MachineConfig& c) {
  const toml::table* t = root.sub("gpio");
  if (!t) return;
  Reader r(root.file(), *t, "gpio");
  r.only({"chip", "start_line", "trigger_line", "output_line"});
  GpioConfig g;
  r.get("chip", g.chip, true);
  r.check("chip", !g.chip.empty(), "must name a gpiochip, e.g. gpiochip0");
  r.get_int("start_line", g.start_line, -1, 1023);
  r.get_int("trigger_line", g.trigger_line, -1, 1023);
  r.get_int("output_line", g.output_line, -1, 1023);
  c.gpio = g;
}

void read_sampler(const Reader& root, MachineConfig& c) {
  const toml::table* t = root.sub("sampler");
  if (!t) return;
  Reader r(root.file(), *t, "sampler");
  r.only({"rate_hz", "realtime", "cpu_affinity", "fifo_priority", "ring_capacity"});
  SamplerConfig& s = c.sampler;
  r.get("rate_hz", s.rate_hz);
  r.check("rate_hz", s.rate_hz > 0.0 && s.rate_hz <= 100000.0, "must be in (0, 100000]");
  r.get("realtime", s.realtime);
  r.get_int("cpu_affinity", s.cpu_affinity, -1, 1023);
  r.get_int("fifo_priority", s.fifo_priority, 1, 99);
  r.get_int("ring_capacity", s.ring_capacity, 2, 1LL << 26);
}

void read_scan(const Reader& root, MachineConfig& c) {
  const toml::table* t = root.sub("scan");
  if (!t) return;
  Reader r(root.file(), *t, "scan");
  r.only({"method",
          "dx_mm",
          "s2",
          "s3",
          "s4",
          "N",
          "single_sensor",
          "sensors",
          "slide_stage",
          "sensor_stage",
          "slide_start_mm",
          "sensor_stage_origin_mm",
          "averages",
          "settle_ms",
          "plan",
          "d_mm",
          "displacement_points",
          "scan2_order",
          "workpiece_sensor",
          "reference_sensor",
          "reference_stage",
          "output_dir"});
  ScanConfig& s = c.scan;
  std::string method = "four_sensor";
  r.get("method", method);
  if (method == "four_sensor")
    s.method = ScanMethod::four_sensor;
  else if (method == "displacement")
    s.method = ScanMethod::displacement;
  else if (method == "both")
    s.method = ScanMethod::both;
  else
    r.fail("method", "'" + method + "' is not one of four_sensor, displacement, both");
  auto& g = s.geometry;
  r.get("dx_mm", g.dx_mm);
  r.check("dx_mm", g.dx_mm > 0.0, "must be > 0");
  r.get_int("s2", g.s2, 1, 100000);
  r.get_int("s3", g.s3, 1, 100000);
  r.get_int("s4", g.s4, 1, 100000);
  r.get_int("N", g.N, 2, 10000000);
  r.check("N", g.positions() >= 2,
          "N = " + std::to_string(g.N) + " must exceed s2 + s3 + s4 + 1 = " +
              std::to_string(g.s2 + g.s3 + g.s4 + 1) + " (at least two slide positions)");
  r.get("single_sensor", s.single_sensor);
  s.sensors = read_string_list(r, "sensors");
  r.get("slide_stage", s.slide_stage);
  r.get("sensor_stage", s.sensor_stage);
  r.get("slide_start_mm", s.slide_start_mm);
  r.get("sensor_stage_origin_mm", s.sensor_stage_origin_mm);
  r.get_int("averages", s.averages, 1, 1000000);
  r.get_int("settle_ms", s.settle_ms, 0, 600000);
  std::string plan = core::to_string(s.plan);
  r.get("plan", plan);
  try {
    s.plan = core::scan_sequence_kind_from_string(plan);
  } catch (const std::invalid_argument& e) {
    r.fail("plan", e.what());
  }
  r.check("plan", s.single_sensor || s.plan == core::ScanSequenceKind::single,
          "a plan other than single needs single_sensor = true (one sensor moved to the "
          "configurations, one traverse each)");
  r.get("d_mm", s.d_mm);
  r.get_int("displacement_points", s.displacement_points, 0, 10000000);
  std::string scan2_order = core::to_string(s.scan2_order);
  r.get("scan2_order", scan2_order);
  try {
    s.scan2_order = core::displacement_scan_order_from_string(scan2_order);
  } catch (const std::invalid_argument& e) {
    r.fail("scan2_order", e.what());
  }
  r.get("workpiece_sensor", s.workpiece_sensor);
  r.get("reference_sensor", s.reference_sensor);
  r.get("reference_stage", s.reference_stage);
  std::string out = s.output_dir.string();
  r.get("output_dir", out);
  r.check("output_dir", !out.empty(), "must not be empty");
  s.output_dir = out;

  auto stage_with_role = [&](const std::string& key, const std::string& name, StageRole role) {
    if (name.empty()) r.fail("", "missing required key '" + key + "'");
    const StageConfig* st = c.find_stage(name);
    r.check(key, st != nullptr, "no [[stage]] named '" + name + "'");
    r.check(
        key, st->role == role,
        "stage '" + name + "' has role " + to_string(st->role) + ", expected " + to_string(role));
  };
  auto sensor_exists = [&](const std::string& key, const std::string& name) {
    if (name.empty()) r.fail("", "missing required key '" + key + "'");
    r.check(key, c.find_sensor(name) != nullptr, "no [[sensor]] named '" + name + "'");
  };
  if (s.method != ScanMethod::displacement) {
    const std::size_t want = s.single_sensor ? 1 : 4;
    r.check("sensors", s.sensors.size() == want,
            "has " + std::to_string(s.sensors.size()) + " names; " +
                (s.single_sensor ? "single_sensor = true needs exactly 1"
                                 : "single_sensor = false needs exactly 4 (configuration order)"));
    for (const auto& n : s.sensors)
      sensor_exists("sensors", n);
    stage_with_role("slide_stage", s.slide_stage, StageRole::slide);
    if (s.single_sensor) stage_with_role("sensor_stage", s.sensor_stage, StageRole::sensor_stage);
  }
  if (s.method != ScanMethod::four_sensor) {
    r.check("d_mm", s.d_mm > 0.0, "must be > 0");
    sensor_exists("workpiece_sensor", s.workpiece_sensor);
    sensor_exists("reference_sensor", s.reference_sensor);
    r.check("reference_sensor", s.reference_sensor != s.workpiece_sensor,
            "must differ from workpiece_sensor");
    stage_with_role("slide_stage", s.slide_stage, StageRole::slide);
    stage_with_role("reference_stage", s.reference_stage, StageRole::reference_piece);
  }
}

void read_simulator(const Reader& root, MachineConfig& c) {
  const toml::table* t = root.sub("simulator");
  if (!t) return;
  Reader r(root.file(), *t, "simulator");
  r.only({"embedded", "host", "port", "preset", "S_um", "gamma_urad", "f_um", "e_um", "w_um",
          "r_um", "m_um", "noise_sigma_um", "drift_um_per_s", "stage_speed_mm_s", "settle_ms",
          "seed", "faults", "gain"});
  SimulatorConfig& s = c.simulator;
  r.get("embedded", s.embedded);
  r.get("host", s.host);
  r.check("host", s.host == "127.0.0.1" || s.host == "::1",
          "'" + s.host + "': the simulator binds to loopback only (127.0.0.1 or ::1)");
  r.get_int("port", s.port, 0, 65535);
  r.get("preset", s.preset);
  r.check(
      "preset", s.preset.empty() || s.preset == "zhao2019_example1",
      "'" + s.preset + "' is not one of \"zhao2019_example1\", \"\" (use S_um, gamma_urad, f_um)");
  s.S_um = read_profile(r, "S_um");
  s.gamma_urad = read_profile(r, "gamma_urad");
  s.f_um = read_profile(r, "f_um");
  s.w_um = read_profile(r, "w_um");
  s.r_um = read_profile(r, "r_um");
  s.m_um = read_profile(r, "m_um");
  if (const toml::node* n = t->get("e_um")) {
    const toml::array* arr = n->as_array();
    if (!arr || arr->size() != 4)
      r.fail("e_um", "expected 4 numbers e_1..e_4 (µm), e.g. [0.0, 1.5, -2.0, 0.7]");
    for (std::size_t i = 0; i < 4; ++i) {
      auto v = arr->get(i)->value<double>();
      if (!v || !std::isfinite(*v)) r.fail("e_um", "every element must be a finite number");
      s.e_um[i] = *v;
    }
  }
  if (const toml::node* n = t->get("gain")) {
    const toml::array* arr = n->as_array();
    if (!arr || arr->size() != 4)
      r.fail("gain", "expected 4 numbers, the gain of configurations 1..4, e.g. [1, 1, 1.05, 1]");
    for (std::size_t i = 0; i < 4; ++i) {
      auto v = arr->get(i)->value<double>();
      if (!v || !(*v > 0.5 && *v < 2)) r.fail("gain", "every element must be a number in (0.5, 2)");
      s.gain[i] = *v;
    }
  }
  r.get("noise_sigma_um", s.noise_sigma_um);
  r.check("noise_sigma_um", s.noise_sigma_um >= 0.0, "must be >= 0");
  r.get("drift_um_per_s", s.drift_um_per_s);
  r.get("stage_speed_mm_s", s.stage_speed_mm_s);
  r.check("stage_speed_mm_s", s.stage_speed_mm_s > 0.0, "must be > 0");
  r.get_int("settle_ms", s.settle_ms, 0, 600000);
  r.get_int("seed", s.seed, 0, std::numeric_limits<long long>::max());
  if (const toml::table* ft = r.sub("faults")) {
    Reader f(r.file(), *ft, "simulator.faults");
    f.only({"hang_after_requests", "hang_ms", "drop_after_requests", "exception_after_requests",
            "exception_count", "exception_code", "out_of_range_sensor"});
    SimulatorFaults& x = s.faults;
    f.get_int("hang_after_requests", x.hang_after_requests, 0, std::numeric_limits<long>::max());
    f.get_int("hang_ms", x.hang_ms, 0, 3600000);
    f.get_int("drop_after_requests", x.drop_after_requests, 0, std::numeric_limits<long>::max());
    f.get_int("exception_after_requests", x.exception_after_requests, 0,
              std::numeric_limits<long>::max());
    f.get_int("exception_count", x.exception_count, 1, 1000000);
    f.get_int("exception_code", x.exception_code, 1, 11);
    f.get("out_of_range_sensor", x.out_of_range_sensor);
    if (!x.out_of_range_sensor.empty())
      f.check("out_of_range_sensor", c.find_sensor(x.out_of_range_sensor) != nullptr,
              "no [[sensor]] named '" + x.out_of_range_sensor + "'");
  }
}

std::string one_of(const std::vector<std::string>& names) {
  std::string out;
  for (const auto& n : names)
    out += (out.empty() ? "\"" : ", \"") + n + "\"";
  return out;
}

void read_separation(const Reader& root, MachineConfig& c) {
  const toml::table* t = root.sub("separation");
  if (!t) return;
  Reader r(root.file(), *t, "separation");
  r.only({"gauge", "lambda_rule", "lambda_min", "lambda_max", "fixed_lambda", "threads"});
  SeparationConfig& s = c.separation;
  std::string name;
  if (t->contains("gauge")) {
    r.get("gauge", name);
    const auto g = core::curvature_gauge_from_string(name);
    if (!g)
      r.fail("gauge", "'" + name + "' is not one of " + one_of(core::curvature_gauge_names()));
    s.gauge = *g;
  }
  if (t->contains("lambda_rule")) {
    r.get("lambda_rule", name);
    const auto l = core::lambda_rule_from_string(name);
    if (!l)
      r.fail("lambda_rule", "'" + name + "' is not one of " + one_of(core::lambda_rule_names()));
    s.lambda_rule = *l;
  }
  r.get("lambda_min", s.lambda_min);
  r.check("lambda_min", s.lambda_min >= 0, "must be >= 0 (0 = automatic)");
  r.get("lambda_max", s.lambda_max);
  r.check("lambda_max", s.lambda_max >= 0, "must be >= 0 (0 = automatic)");
  r.check("lambda_max", s.lambda_max == 0 || s.lambda_max > s.lambda_min,
          "must be above lambda_min");
  r.get("fixed_lambda", s.fixed_lambda);
  r.check("fixed_lambda", s.fixed_lambda >= 0, "must be >= 0");
  r.check("fixed_lambda", s.lambda_rule != core::LambdaRule::fixed || s.fixed_lambda > 0,
          "lambda_rule = \"fixed\" needs fixed_lambda > 0");
  r.get_int("threads", s.threads, 1, 64);
  std::string why;
  if (!s.is_valid(&why)) r.fail("gauge", why);
}

void read_refine(const Reader& root, MachineConfig& c) {
  const toml::table* t = root.sub("refine");
  if (!t) return;
  Reader r(root.file(), *t, "refine");
  r.only({"enabled", "alpha"});
  r.get("enabled", c.refine.enabled);
  r.get("alpha", c.refine.alpha);
  // A significance level: 0 would never add anything, 1 would add every candidate.
  r.check("alpha", c.refine.alpha > 0.0 && c.refine.alpha < 1.0, "must be in (0, 1)");
}

void read_report(const Reader& root, MachineConfig& c) {
  const toml::table* t = root.sub("report");
  if (!t) return;
  Reader r(root.file(), *t, "report");
  r.only(
      {"machine", "operator", "instrument", "temperature_c", "straightness_tolerance_um", "pdf"});
  ReportConfig& p = c.report;
  r.get("machine", p.machine);
  r.get("operator", p.operator_name);
  r.get("instrument", p.instrument);
  r.get("pdf", p.pdf);
  if (t->contains("temperature_c")) {
    double v = 0;
    r.get("temperature_c", v);
    r.check("temperature_c", v > -50 && v < 100, "must be in (-50, 100) degC");
    p.temperature_c = v;
  }
  if (t->contains("straightness_tolerance_um")) {
    double v = 0;
    r.get("straightness_tolerance_um", v);
    r.check("straightness_tolerance_um", v > 0, "must be > 0");
    p.straightness_tolerance_um = v;
  }
}

void read_mqtt(const Reader& root, MachineConfig& c) {
  const toml::table* t = root.sub("mqtt");
  if (!t) return;
  Reader r(root.file(), *t, "mqtt");
  r.only({"host", "port", "machine", "client_id", "topic_prefix", "qos", "keepalive_s", "username",
          "password_file", "tls_ca_file", "tls_cert_file", "tls_key_file", "queue_dir", "commands",
          "straightness_tolerance_um"});
  MqttConfig m;
  r.get("host", m.host);
  r.check("host", !m.host.empty(), "must name the broker");
  r.get_int("port", m.port, 1, 65535);
  r.get("machine", m.machine, true);
  // A topic level: no wildcards, no separator, nothing a subscription could misread.
  auto level_ok = [](const std::string& v) {
    return !v.empty() && v.find_first_of("/+#") == std::string::npos &&
           std::all_of(v.begin(), v.end(), [](char ch) { return ch > ' ' && ch != 0x7f; });
  };
  r.check("machine", level_ok(m.machine),
          "must be one topic level: no '/', '+', '#', spaces or control characters");
  r.get("client_id", m.client_id);
  r.get("topic_prefix", m.topic_prefix);
  r.check("topic_prefix",
          !m.topic_prefix.empty() && m.topic_prefix.find_first_of("+#") == std::string::npos &&
              m.topic_prefix.front() != '/' && m.topic_prefix.back() != '/',
          "must be a topic without wildcards and without a leading or trailing '/'");
  r.get_int("qos", m.qos, 1, 2);
  r.get_int("keepalive_s", m.keepalive_s, 5, 3600);
  r.get("username", m.username);
  std::string s;
  r.get("password_file", s);
  m.password_file = s;
  r.check("password_file", m.password_file.empty() || !m.username.empty(),
          "a password needs a username");
  s.clear();
  r.get("tls_ca_file", s);
  m.tls_ca_file = s;
  s.clear();
  r.get("tls_cert_file", s);
  m.tls_cert_file = s;
  s.clear();
  r.get("tls_key_file", s);
  m.tls_key_file = s;
  r.check("tls_cert_file", m.tls_cert_file.empty() == m.tls_key_file.empty(),
          "tls_cert_file and tls_key_file go together");
  r.check("tls_cert_file", m.tls_cert_file.empty() || !m.tls_ca_file.empty(),
          "a client certificate needs tls_ca_file");
  s.clear();
  r.get("queue_dir", s);
  m.queue_dir = s;
  r.get("commands", m.commands);
  r.get("straightness_tolerance_um", m.straightness_tolerance_um);
  r.check("straightness_tolerance_um", m.straightness_tolerance_um >= 0.0,
          "must be >= 0 (0 = no alarm)");
  c.mqtt = m;
}

void read_axes(const Reader& root, MachineConfig& c) {
  c.axes.slide_start_mm = c.scan.slide_start_mm;
  const toml::table* t = root.sub("axes");
  if (!t) return;
  Reader r(root.file(), *t, "axes");
  r.only({"input", "output", "scan_direction", "reading_sign"});
  for (const auto& [key, axis] : {std::pair<const char*, char*>{"input", &c.axes.input_axis},
                                  {"output", &c.axes.output_axis}}) {
    std::string v(1, *axis);
    r.get(key, v);
    const char a = core::parse_linear_axis(v);
    r.check(key, a != 0, "'" + v + "' is not X, Y or Z");
    *axis = a;
  }
  r.check("output", c.axes.output_axis != c.axes.input_axis,
          "equals input: the sensors read across the moving axis");
  r.get_int("scan_direction", c.axes.scan_direction, -1, 1);
  r.check("scan_direction", c.axes.scan_direction != 0,
          "must be 1 (the scan runs towards + of the input axis) or -1");
  r.get_int("reading_sign", c.axes.reading_sign, -1, 1);
  r.check("reading_sign", c.axes.reading_sign != 0,
          "must be 1 (a reading grows when the carriage moves towards + output) or -1");
}

void read_compensation(const Reader& root, MachineConfig& c) {
  const toml::table* t = root.sub("compensation");
  if (!t) return;
  Reader r(root.file(), *t, "compensation");
  auto& cc = c.compensation;
  for (const auto& [k, v] : *t) {
    const std::string key(k.str());
    if (key == "formats") {
      cc.tables.formats.clear();
      for (const auto& name : read_string_list(r, "formats")) {
        const auto f = parse_compensation_format(name);
        r.check("formats", f.has_value(),
                "'" + name + "' is not one of " + compensation_format_names());
        cc.tables.formats.push_back(*f);
      }
      r.check("formats", !cc.tables.formats.empty(), "must name at least one format");
    } else if (key == "remove_line") {
      std::string line;
      r.get("remove_line", line);
      if (line == "none") {
        cc.profile.remove_line.reset();
      } else {
        const auto l = core::parse_reference_line(line);
        r.check("remove_line", l.has_value(),
                "'" + line + "' is not one of end_points, least_squares, minimum_zone, none");
        cc.profile.remove_line = *l;
      }
    } else if (const auto f = parse_compensation_format(key)) {
      // A format's own parameters: the parser passes them on as text and lets the format judge.
      const toml::table* ft = r.sub(key);
      CncParameters params;
      for (const auto& [pk, pv] : *ft) {
        std::string text;
        if (pv.is_string()) {
          text = pv.as_string()->get();
        } else if (pv.is_integer()) {
          text = std::to_string(pv.as_integer()->get());
        } else if (pv.is_floating_point()) {
          char buf[48];
          std::snprintf(buf, sizeof buf, "%.17g", pv.as_floating_point()->get());
          text = buf;
        } else {
          throw ConfigError(root.file(), line_of(pv),
                            "compensation." + key + "." + std::string(pk.str()),
                            "expected a string or a number");
        }
        params[std::string(pk.str())] = text;
      }
      try {
        compensation_writer(*f).validate(params);
      } catch (const std::invalid_argument& e) {
        // "<format>.<key>: problem": point at the key's line.
        const std::string msg = e.what();
        const auto dot = msg.find('.'), colon = msg.find(": ");
        const std::string pkey =
            dot != std::string::npos && colon != std::string::npos && colon > dot
                ? msg.substr(dot + 1, colon - dot - 1)
                : std::string();
        const toml::node* n = pkey.empty() ? nullptr : ft->get(pkey);
        throw ConfigError(
            root.file(), n ? line_of(*n) : line_of(*ft),
            "compensation." + (colon == std::string::npos ? key : msg.substr(0, colon)),
            msg.substr(colon == std::string::npos ? 0 : colon + 2));
      }
      cc.tables.parameters[*f] = std::move(params);
    } else {
      throw ConfigError(root.file(), line_of(v), "compensation." + key,
                        "unknown key (allowed here: formats, remove_line, and a table per "
                        "format: " +
                            compensation_format_names() + ")");
    }
  }
}

MachineConfig build(const toml::table& root, const std::string& name) {
  MachineConfig c;
  c.source = name;
  Reader r(name, root, "");
  r.only({"bus", "sensor", "stage", "gpio", "sampler", "scan", "axes", "compensation", "separation",
          "refine", "report", "simulator", "mqtt"});
  read_buses(name, root, c);
  if (c.buses.empty()) throw ConfigError(name, 0, "bus", "at least one [[bus]] is required");
  read_sensors(name, root, c);
  read_stages(name, root, c);
  read_gpio(r, c);
  read_sampler(r, c);
  read_scan(r, c);
  read_axes(r, c);
  read_compensation(r, c);
  read_separation(r, c);
  read_refine(r, c);
  read_report(r, c);
  read_simulator(r, c);
  read_mqtt(r, c);
  // Port 0 means "the embedded simulator's ephemeral port"; without it nothing fills it in.
  for (std::size_t i = 0; i < c.buses.size(); ++i) {
    const auto& b = c.buses[i];
    if (b.kind == BusKind::tcp && b.port == 0 && !c.simulator.embedded) {
      const toml::node* n = root.get("bus")->as_array()->get(i)->as_table()->get("port");
      throw ConfigError(name, n ? line_of(*n) : 0, "bus[" + std::to_string(i) + "].port",
                        "port 0 is only allowed with [simulator] embedded = true");
    }
  }
  return c;
}

}  // namespace

MachineConfig parse_machine_config(const std::string& toml_text, const std::string& name) {
  toml::table root;
  try {
    root = toml::parse(toml_text, name);
  } catch (const toml::parse_error& e) {
    throw ConfigError(name, static_cast<int>(e.source().begin.line), "",
                      "TOML syntax error: " + std::string(e.description()));
  }
  return build(root, name);
}

MachineConfig load_machine_config(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw ConfigError(file.string(), 0, "", "cannot open the config file");
  std::ostringstream ss;
  ss << in.rdbuf();
  MachineConfig c = parse_machine_config(ss.str(), file.string());
  c.source = file;
  return c;
}

bool SeparationConfig::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (threads < 1 || threads > 64)
    return fail("threads = " + std::to_string(threads) + " must be in 1..64");
  if (!(lambda_min >= 0) || !(lambda_max >= 0) || (lambda_max > 0 && !(lambda_max > lambda_min)))
    return fail("lambda range [" + std::to_string(lambda_min) + ", " + std::to_string(lambda_max) +
                "] must be 0 (automatic) or 0 <= lambda_min < lambda_max");
  if (lambda_rule == core::LambdaRule::fixed && !(fixed_lambda > 0))
    return fail("lambda_rule fixed needs fixed_lambda > 0");
  std::string w;
  if (!options().is_valid(&w)) return fail(w);
  return true;
}

core::FourSensorOptions SeparationConfig::options() const {
  core::FourSensorOptions o = core::options_for_gauge(gauge);
  if (lambda_rule) o.rule = *lambda_rule;
  o.fixed_lambda = fixed_lambda;
  o.lcurve.lambda_min = lambda_min;
  o.lcurve.lambda_max = lambda_max;
  o.lcurve.threads = threads;
  o.search.threads = threads;
  return o;
}

}  // namespace errsep::io

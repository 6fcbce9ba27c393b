#include "errsep/drivers/modbus_device_simulator.hpp"

#include <modbus.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>
#include <optional>
#include <random>
#include <stdexcept>
#include <vector>

#include "errsep/acq/register_map.hpp"
#include "errsep/core/four_sensor_model.hpp"
#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/io/cnc/compensation_format.hpp"

namespace errsep::drivers {
namespace {

double now_s() {
  using namespace std::chrono;
  return duration<double>(steady_clock::now().time_since_epoch()).count();
}

/// A stage moving at constant speed from p0 (at t0) toward target.
struct SimStage {
  const io::StageConfig* cfg = nullptr;
  double p0_mm = 0.0, target_mm = 0.0, t0_s = -1e9, speed_mm_s = 50.0, settle_s = 0.0;
  bool stopped = false;
  bool fault = false;
  unsigned fault_code = 0;

  double position(double t) const {
    const double d = target_mm - p0_mm;
    const double travelled = std::max(0.0, (t - t0_s) * speed_mm_s);
    if (travelled >= std::abs(d)) return target_mm;
    return p0_mm + std::copysign(travelled, d);
  }
  bool in_position(double t) const {
    return !stopped && !fault && t >= t0_s + std::abs(target_mm - p0_mm) / speed_mm_s + settle_s;
  }
  void move(double t, double target) {
    p0_mm = position(t);
    target_mm = target;
    t0_s = t;
    stopped = false;
  }
  void stop(double t) {
    p0_mm = position(t);
    target_mm = p0_mm;
    t0_s = t;
    stopped = true;
  }
};

enum class SensorRole { unused, single, fixed, workpiece, reference };

struct SimSensor {
  const io::SensorConfig* cfg = nullptr;
  SensorRole role = SensorRole::unused;
  int config_index = 0;  // fixed: configuration 0..3
};

// Which register space a spec lives in, and how many words/bits it spans.
int space_of(const io::RegisterSpec& s) {
  return static_cast<int>(s.kind);
}

}  // namespace

struct ModbusDeviceSimulator::Impl {
  io::MachineConfig cfg;
  core::SlidewayTruth truth;
  std::optional<io::ControllerTable> compensation;  ///< the controller's table, if loaded
  std::array<double, 4> offsets_mm{};
  std::vector<SimStage> stages;
  std::vector<SimSensor> sensors;
  SimStage* slide = nullptr;
  SimStage* sensor_stage = nullptr;
  SimStage* reference_stage = nullptr;
  double t_start_s = now_s();
  std::mt19937_64 rng;
  std::normal_distribution<double> normal{0.0, 1.0};

  modbus_mapping_t* map = nullptr;
  std::unique_ptr<ModbusTcpServer> server;

  std::mutex mu;  // guards faults, fault counters and stage faults against inject()
  io::SimulatorFaults faults;
  std::uint64_t fault_base = 0;  // request count when the schedule was (re)set
  double hang_until_s = 0.0;
  bool hang_forever = false;
  bool hang_done = false, drop_done = false;
  int exceptions_left = -1;  // -1: exception fault not yet triggered

  std::atomic<std::uint64_t> requests{0}, replies{0}, exceptions_sent{0}, ignored{0}, drops{0};

  Impl(const io::MachineConfig& c, ModbusTcpServerOptions so) : cfg(c), rng(c.simulator.seed) {
    const auto& sim = cfg.simulator;
    if (sim.host != "127.0.0.1" && sim.host != "::1")
      throw std::runtime_error("simulator: host '" + sim.host +
                               "' is not loopback; the simulator binds to 127.0.0.1 or ::1 only");
    const auto& g = cfg.scan.geometry;
    const auto off = g.offsets_samples();
    for (int i = 0; i < 4; ++i)
      offsets_mm[static_cast<std::size_t>(i)] = off[i] * g.dx_mm;
    if (sim.preset == "zhao2019_example1") {
      truth = core::zhao2019_example1(g);
    } else {
      truth.S_um = [p = sim.S_um](double x) { return p.eval(x); };
      truth.gamma_rad = [p = sim.gamma_urad](double x) { return 1e-6 * p.eval(x); };
      truth.f_um = [p = sim.f_um](double x) { return p.eval(x); };
    }
    truth.e_um = sim.e_um;
    faults = sim.faults;
    if (!sim.compensation_table.empty()) {
      compensation = io::read_compensation_file(sim.compensation_table);
      const auto& ct = *compensation;
      const auto& a = cfg.axes;
      if ((ct.input_axis && ct.input_axis != a.input_axis) ||
          (ct.output_axis && ct.output_axis != a.output_axis))
        throw std::runtime_error(
            "simulator: " + sim.compensation_table.string() + " compensates " +
            std::string(1, ct.output_axis ? ct.output_axis : '?') + " as a function of " +
            std::string(1, ct.input_axis ? ct.input_axis : '?') + ", but the scan of " +
            cfg.source.string() + " measures " + a.symbol() + " ([axes] input/output)");
    }

    stages.reserve(cfg.stages.size());
    for (const auto& s : cfg.stages) {
      SimStage st;
      st.cfg = &s;
      st.speed_mm_s = sim.stage_speed_mm_s;
      st.settle_s = sim.settle_ms / 1000.0;
      stages.push_back(st);
    }
    for (auto& st : stages) {
      if (st.cfg->name == cfg.scan.slide_stage) slide = &st;
      if (st.cfg->name == cfg.scan.sensor_stage) sensor_stage = &st;
      if (st.cfg->name == cfg.scan.reference_stage) reference_stage = &st;
    }
    for (const auto& s : cfg.sensors) {
      SimSensor ss;
      ss.cfg = &s;
      const auto& sc = cfg.scan;
      const auto it = std::find(sc.sensors.begin(), sc.sensors.end(), s.name);
      if (it != sc.sensors.end()) {
        if (sc.single_sensor) {
          ss.role = SensorRole::single;
        } else {
          ss.role = SensorRole::fixed;
          ss.config_index = static_cast<int>(it - sc.sensors.begin());
        }
      } else if (s.name == sc.workpiece_sensor) {
        ss.role = SensorRole::workpiece;
      } else if (s.name == sc.reference_sensor) {
        ss.role = SensorRole::reference;
      }
      sensors.push_back(ss);
    }
    check_overlaps();
    build_mapping();
    update(now_s());
    so.host = sim.host;
    so.port = sim.port;
    server = std::make_unique<ModbusTcpServer>(
        "simulator", so,
        [this](_modbus* ctx, const std::uint8_t* q, int length) { return handle(ctx, q, length); });
  }

  ~Impl() {
    server.reset();  // its sockets and context first
    if (map) modbus_mapping_free(map);
  }

  // Refuses configs where two things would share a register (one address space for all units).
  void check_overlaps() {
    std::map<std::pair<int, int>, std::string> owner;
    auto claim = [&](const io::RegisterSpec& r, const std::string& who) {
      for (int a = r.address; a < r.address + r.word_count(); ++a) {
        auto [it, fresh] = owner.emplace(std::make_pair(space_of(r), a), who);
        if (!fresh && it->second != who)
          throw std::runtime_error("simulator: " + who + " and " + it->second + " share " +
                                   io::to_string(r.kind) + " register " + std::to_string(a) +
                                   " (the simulator serves one address space for all units)");
      }
    };
    for (const auto& s : cfg.sensors)
      claim(s.reg, "sensor '" + s.name + "'");
    for (const auto& s : cfg.stages) {
      const std::string who = "stage '" + s.name + "'";
      claim(s.target_position, who);
      if (!(s.actual_position.kind == s.target_position.kind &&
            s.actual_position.address == s.target_position.address))
        claim(s.actual_position, who);
      claim(s.status, who);
      claim(s.stop_coil, who);
      if (s.fault_code) claim(*s.fault_code, who);
      if (s.speed) claim(*s.speed, who);
    }
  }

  void build_mapping() {
    int max_addr[3] = {-1, -1, -1};
    auto see = [&](const io::RegisterSpec& r) {
      int& m = max_addr[space_of(r)];
      m = std::max(m, r.address + r.word_count() - 1);
    };
    for (const auto& s : cfg.sensors)
      see(s.reg);
    for (const auto& s : cfg.stages) {
      see(s.target_position);
      see(s.actual_position);
      see(s.status);
      see(s.stop_coil);
      if (s.fault_code) see(*s.fault_code);
      if (s.speed) see(*s.speed);
    }
    // input, holding, coil
    map = modbus_mapping_new_start_address(0, static_cast<unsigned>(max_addr[2] + 1), 0, 0, 0,
                                           static_cast<unsigned>(max_addr[1] + 1), 0,
                                           static_cast<unsigned>(max_addr[0] + 1));
    if (!map)
      throw std::runtime_error(std::string("simulator: cannot allocate the register map: ") +
                               modbus_strerror(errno));
    // Holding registers read back what was last commanded: start with the stages' targets.
    for (auto& st : stages) {
      if (st.cfg->speed) put(*st.cfg->speed, st.speed_mm_s);
      put(st.cfg->target_position, st.target_mm);
    }
  }

  void put(const io::RegisterSpec& r, double value) {
    std::uint16_t w[2] = {0, 0};
    acq::encode(r, value, w);
    if (r.kind == io::RegisterKind::coil) {
      map->tab_bits[r.address] = w[0] ? 1 : 0;
      return;
    }
    std::uint16_t* tab =
        r.kind == io::RegisterKind::input ? map->tab_input_registers : map->tab_registers;
    for (int i = 0; i < r.word_count(); ++i)
      tab[r.address + i] = w[i];
  }
  double get(const io::RegisterSpec& r) const {
    if (r.kind == io::RegisterKind::coil) return map->tab_bits[r.address] ? 1.0 : 0.0;
    const std::uint16_t* tab =
        r.kind == io::RegisterKind::input ? map->tab_input_registers : map->tab_registers;
    return acq::decode(r, tab + r.address);
  }

  // A loaded compensation table moves the carriage by c(p) along the output axis; the reading
  // sees reading_sign * c (core/machine_axes.hpp), like a change of S.
  double compensation_um(double p) const {
    return compensation ? cfg.axes.reading_sign * compensation->apply_um(p) : 0.0;
  }

  double sensor_value(const SimSensor& s, double t) {
    // The truth is laid over the scan (x from its start); the machine position is the slide's.
    const double p = slide ? slide->position(t) : cfg.scan.slide_start_mm;
    const double x = (p - cfg.scan.slide_start_mm) * cfg.axes.scan_direction;
    double v = 0.0;
    switch (s.role) {
      case SensorRole::single: {
        // Zhao 2019 Eq. (1) with O = the sensor stage's offset from configuration 1.
        const double o =
            sensor_stage ? sensor_stage->position(t) - cfg.scan.sensor_stage_origin_mm : 0.0;
        std::size_t nearest = 0;
        for (std::size_t i = 1; i < 4; ++i)
          if (std::abs(o - offsets_mm[i]) < std::abs(o - offsets_mm[nearest])) nearest = i;
        v = cfg.simulator.gain[nearest] *
            (core::four_sensor_reading_um(truth, x, o) + truth.e_um[nearest] + compensation_um(p));
        break;
      }
      case SensorRole::fixed: {
        const auto i = static_cast<std::size_t>(s.config_index);
        v = cfg.simulator.gain[i] * (core::four_sensor_reading_um(truth, x, offsets_mm[i]) +
                                     truth.e_um[i] + compensation_um(p));
        break;
      }
      case SensorRole::workpiece:  // Haramiishi 2024 Eq. (1): S1 = w(x) + m(x)
        v = cfg.simulator.w_um.eval(x) + cfg.simulator.m_um.eval(x);
        break;
      case SensorRole::reference: {  // Eq. (2)/(3): S2 = r(x + d) + m(x), d = piece position
        const double d = reference_stage ? reference_stage->position(t) : 0.0;
        v = cfg.simulator.r_um.eval(x + d) + cfg.simulator.m_um.eval(x);
        break;
      }
      case SensorRole::unused:
        break;
    }
    v += cfg.simulator.drift_um_per_s * (t - t_start_s);
    if (cfg.simulator.noise_sigma_um > 0.0) v += cfg.simulator.noise_sigma_um * normal(rng);
    return v;
  }

  // Brings every served register up to time t.  Caller holds mu.
  void update(double t) {
    for (auto& st : stages) {
      const auto& c = *st.cfg;
      // The actual position may share the target's holding register (a drive that reports
      // where it is in the register it was commanded with); then it is overwritten here.
      put(c.actual_position, st.position(t));
      std::uint16_t bits = 0;
      if (st.in_position(t)) bits |= static_cast<std::uint16_t>(1u << c.in_position_bit);
      if (st.fault) bits |= static_cast<std::uint16_t>(1u << c.fault_bit);
      put(c.status, bits);
      if (c.fault_code) put(*c.fault_code, st.fault ? st.fault_code : 0);
    }
    for (const auto& s : sensors) {
      double v = sensor_value(s, t);
      if (!faults.out_of_range_sensor.empty() && s.cfg->name == faults.out_of_range_sensor)
        v = s.cfg->range_max_um + 1000.0;
      put(s.cfg->reg, v);
    }
  }

  // After a write request was applied to the mapping: new targets, speeds, stop coils.
  void after_write(const std::uint8_t* q, int hl, double t) {
    const int fc = q[hl];
    if (fc != MODBUS_FC_WRITE_SINGLE_REGISTER && fc != MODBUS_FC_WRITE_MULTIPLE_REGISTERS &&
        fc != MODBUS_FC_WRITE_SINGLE_COIL && fc != MODBUS_FC_WRITE_MULTIPLE_COILS)
      return;
    const int addr = (q[hl + 1] << 8) | q[hl + 2];
    int count = 1;
    if (fc == MODBUS_FC_WRITE_MULTIPLE_REGISTERS || fc == MODBUS_FC_WRITE_MULTIPLE_COILS)
      count = (q[hl + 3] << 8) | q[hl + 4];
    const bool coil = fc == MODBUS_FC_WRITE_SINGLE_COIL || fc == MODBUS_FC_WRITE_MULTIPLE_COILS;
    auto touches = [&](const io::RegisterSpec& r) {
      const bool is_coil = r.kind == io::RegisterKind::coil;
      if (is_coil != coil || (!is_coil && r.kind != io::RegisterKind::holding)) return false;
      return addr <= r.address + r.word_count() - 1 && r.address <= addr + count - 1;
    };
    for (auto& st : stages) {
      const auto& c = *st.cfg;
      if (touches(c.stop_coil) && get(c.stop_coil) != 0.0) {
        st.stop(t);
        put(c.stop_coil, 0.0);  // a command, not a state
      }
      if (c.speed && touches(*c.speed)) {
        const double v = get(*c.speed);
        if (std::isfinite(v) && v > 0.0) st.speed_mm_s = v;
      }
      if (touches(c.target_position)) {
        const double target = get(c.target_position);
        if (std::isfinite(target)) st.move(t, target);
      }
    }
  }

  // One request from one client (the server's thread).
  ModbusConnectionAction handle(modbus_t* ctx, const std::uint8_t* q, int rc) {
    using Action = ModbusConnectionAction;
    const std::uint64_t n = requests.fetch_add(1) + 1;
    const double t = now_s();
    std::lock_guard<std::mutex> lock(mu);
    const std::uint64_t k = n - fault_base;  // requests since the fault schedule was set
    // Stop answering: the request is read (so no stale answer is sent later) and dropped.
    if (hang_forever || t < hang_until_s) {
      ignored.fetch_add(1);
      return Action::keep;
    }
    if (!hang_done && faults.hang_after_requests > 0 &&
        k >= static_cast<std::uint64_t>(faults.hang_after_requests)) {
      hang_done = true;
      hang_forever = faults.hang_ms == 0;
      hang_until_s = t + faults.hang_ms / 1000.0;
      ignored.fetch_add(1);
      return Action::keep;
    }
    if (!drop_done && faults.drop_after_requests > 0 &&
        k >= static_cast<std::uint64_t>(faults.drop_after_requests)) {
      drop_done = true;
      drops.fetch_add(1);  // before the close: a client that sees the drop also sees the count
      return Action::close_all;
    }
    if (faults.exception_after_requests > 0 && exceptions_left != 0 &&
        k >= static_cast<std::uint64_t>(faults.exception_after_requests)) {
      if (exceptions_left < 0) exceptions_left = faults.exception_count;
      --exceptions_left;
      modbus_reply_exception(ctx, q, static_cast<unsigned>(faults.exception_code));
      exceptions_sent.fetch_add(1);
      return Action::keep;
    }
    update(t);
    if (modbus_reply(ctx, q, rc, map) == -1) return Action::close;
    replies.fetch_add(1);
    after_write(q, modbus_get_header_length(ctx), t);
    return Action::keep;
  }
};

ModbusDeviceSimulator::ModbusDeviceSimulator(const io::MachineConfig& cfg,
                                             ModbusTcpServerOptions server)
    : impl_(std::make_unique<Impl>(cfg, std::move(server))) {}

ModbusDeviceSimulator::~ModbusDeviceSimulator() = default;

const std::string& ModbusDeviceSimulator::host() const noexcept {
  return impl_->cfg.simulator.host;
}

int ModbusDeviceSimulator::listen() {
  port_ = impl_->server->listen();
  return port_;
}

void ModbusDeviceSimulator::run() {
  impl_->server->run(stop_);
}

void ModbusDeviceSimulator::inject(const io::SimulatorFaults& faults) {
  Impl& m = *impl_;
  std::lock_guard<std::mutex> lock(m.mu);
  m.faults = faults;
  m.fault_base = m.requests.load();
  m.hang_until_s = 0.0;
  m.hang_forever = false;
  m.hang_done = m.drop_done = false;
  m.exceptions_left = -1;
}

bool ModbusDeviceSimulator::set_stage_fault(const std::string& stage, bool fault, unsigned code) {
  Impl& m = *impl_;
  std::lock_guard<std::mutex> lock(m.mu);
  for (auto& st : m.stages) {
    if (st.cfg->name != stage) continue;
    if (fault && !st.fault) st.stop(now_s());  // a faulted drive does not keep moving
    st.fault = fault;
    st.fault_code = fault ? code : 0;
    return true;
  }
  return false;
}

SimulatorStats ModbusDeviceSimulator::stats() const noexcept {
  const Impl& m = *impl_;
  SimulatorStats s;
  s.requests = m.requests.load();
  s.replies = m.replies.load();
  s.exceptions_sent = m.exceptions_sent.load();
  s.ignored = m.ignored.load();
  s.drops = m.drops.load();
  const ModbusTcpServerStats t = m.server->stats();
  s.accepted = t.accepted;
  s.clients = t.connections;
  s.evictions = t.evictions;
  s.idle_timeouts = t.idle_timeouts;
  s.frame_timeouts = t.frame_timeouts;
  return s;
}

}  // namespace errsep::drivers

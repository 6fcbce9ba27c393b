#include "errsep/acq/scan_runner.hpp"

#include <array>
#include <atomic>
#include <catch2/catch.hpp>
#include <cmath>
#include <limits>
#include <memory>

#include "errsep/acq/fake_drivers.hpp"
#include "errsep/core/four_sensor_model.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "support/support.hpp"

using namespace errsep;
using namespace errsep::acq;
using namespace std::chrono_literals;

namespace {

// A slideway played by fake stages: S, γ, f and e known exactly (Eq. 1 of Zhao 2019), so every
// recorded average can be checked against the model.
struct FakeMachine {
  core::SlidewayTruth truth;
  core::FourSensorConfig g;
  FakeStage slide{"slide", 2000.0, 1ms};
  FakeStage sensor_stage{"sensor_stage", 2000.0, 1ms};
  FakeStage reference{"reference_piece", 2000.0, 1ms};
  std::vector<std::unique_ptr<FakeSensor>> sensors;

  FakeMachine() {
    g.dx_mm = 2.0;
    g.s2 = 1;
    g.s3 = 1;
    g.s4 = 2;
    g.N = 13;  // P = 9
    truth.f_um = [](double x) { return 0.3 * std::sin(x / 3.0); };
    truth.S_um = [](double x) { return 1e-3 * x * x - 0.02 * x; };
    truth.gamma_rad = [](double x) { return 2e-6 * std::cos(x / 5.0); };
    truth.e_um = {0.0, 1.0, -0.5, 2.0};
    slide.configure();
    sensor_stage.configure();
    reference.configure();
  }
  double expected_um(int config, int n) const {
    const double x = n * g.dx_mm;
    const auto off = g.offsets_mm();
    return core::four_sensor_reading_um(truth, x, off[static_cast<std::size_t>(config)]) +
           truth.e_um[static_cast<std::size_t>(config)];
  }
  // The single sensor: its configuration is wherever the sensor stage is.
  FakeSensor& add_single(FakeSensorFaults faults = {}) {
    sensors.push_back(std::make_unique<FakeSensor>(
        "sensor1",
        [this](std::int64_t) {
          const double o = sensor_stage.position_now_mm();
          const auto off = g.offsets_mm();
          std::size_t nearest = 0;
          for (std::size_t i = 1; i < 4; ++i)
            if (std::fabs(o - off[i]) < std::fabs(o - off[nearest])) nearest = i;
          return core::four_sensor_reading_um(truth, slide.position_now_mm(), o) +
                 truth.e_um[nearest];
        },
        faults));
    sensors.back()->configure();
    return *sensors.back();
  }
  void add_fixed() {
    for (int i = 0; i < 4; ++i) {
      sensors.push_back(
          std::make_unique<FakeSensor>("probe" + std::to_string(i + 1), [this, i](std::int64_t) {
            const auto off = g.offsets_mm();
            return core::four_sensor_reading_um(truth, slide.position_now_mm(),
                                                off[static_cast<std::size_t>(i)]) +
                   truth.e_um[static_cast<std::size_t>(i)];
          }));
      sensors.back()->configure();
    }
  }
  ScanDevices devices() {
    ScanDevices d;
    d.slide = &slide;
    d.sensor_stage = &sensor_stage;
    d.reference_stage = &reference;
    for (auto& s : sensors)
      d.sensors.push_back(s.get());
    return d;
  }
  ScanOptions options() const {
    ScanOptions o;
    o.geometry = g;
    o.averages = 5;
    o.settle_ms = 1;
    o.sampler.rate_hz = 2000.0;
    o.move_timeout_ms = 2000;
    o.ring_capacity = 4096;
    return o;
  }
};

}  // namespace

TEST_CASE("complete four-sensor scan with one sensor on the sensor stage records Eq. (1)") {
  FakeMachine m;
  m.add_single();
  int calls = 0;
  ScanHooks hooks;
  hooks.progress = [&](const ScanProgress& p) {
    ++calls;
    CHECK(p.point == calls);
    CHECK(p.points_total == 36);
  };
  const auto res = run_scan(m.devices(), m.options(), hooks);
  INFO(res.brief_report());
  REQUIRE(res.complete());
  CHECK(res.stop_reason.empty());
  CHECK(calls == 36);
  REQUIRE(res.four_sensor);
  const auto& raw = *res.four_sensor;
  CHECK(raw.complete);
  REQUIRE(raw.positions() == 9);
  for (int i = 0; i < 4; ++i)
    for (int n = 0; n < 9; ++n) {
      INFO("configuration " << i + 1 << ", n = " << n);
      CHECK(raw.m_um[static_cast<std::size_t>(i)][static_cast<std::size_t>(n)] ==
            Approx(m.expected_um(i, n)).margin(1e-9));
    }
  // Configurations are measured one after the other: times increase through the whole scan.
  double last = -1;
  for (std::size_t i = 0; i < 4; ++i)
    for (std::size_t n = 0; n < 9; ++n) {
      CHECK((*raw.t_s)[i][n] > last);
      last = (*raw.t_s)[i][n];
    }
  // Every sample the sampler pushed was drained; K per point went into the averages.
  CHECK(res.counts.samples_consumed == res.counts.samples);
  CHECK(res.counts.samples_averaged == 36u * 5u);
  CHECK(res.counts.overruns == 0);
  CHECK(res.counts.read_errors == 0);
  CHECK(m.slide.stops() == 0);
  CHECK(raw.meta("samples") == std::to_string(res.counts.samples));
  CHECK(raw.meta("outcome") == std::optional<std::string>("complete"));
}

TEST_CASE("complete scan with four fixed sensors, and transient read errors retried") {
  FakeMachine m;
  m.add_fixed();
  FakeSensorFaults flaky;
  flaky.fail_every_n = 3;  // probe 3 fails every third read: still K ok readings per window
  m.sensors[2]->set_faults(flaky);
  const auto res = run_scan(m.devices(), m.options());
  INFO(res.brief_report());
  REQUIRE(res.complete());
  const auto& raw = *res.four_sensor;
  for (int i = 0; i < 4; ++i)
    for (int n = 0; n < 9; ++n)
      CHECK(raw.m_um[static_cast<std::size_t>(i)][static_cast<std::size_t>(n)] ==
            Approx(m.expected_um(i, n)).margin(1e-9));
  CHECK(res.counts.read_errors > 0);
  CHECK(res.counts.reads_by_status[static_cast<std::size_t>(IoStatus::timeout)] ==
        res.counts.read_errors);
  CHECK(raw.meta("read_errors_timeout") == std::to_string(res.counts.read_errors));
}

TEST_CASE("abort mid-scan: stages stopped, data so far kept, result incomplete") {
  FakeMachine m;
  m.add_single();
  std::atomic<bool> abort{false};
  ScanHooks hooks;
  hooks.abort = &abort;
  hooks.progress = [&](const ScanProgress& p) {
    if (p.point == 12) abort = true;  // configuration 2, third point
  };
  const auto res = run_scan(m.devices(), m.options(), hooks);
  CHECK(res.outcome == ScanRunOutcome::aborted);
  CHECK_THAT(res.stop_reason, Catch::Contains("aborted"));
  CHECK(m.slide.stops() >= 1);
  CHECK(m.sensor_stage.stops() >= 1);
  const auto& raw = *res.four_sensor;
  CHECK_FALSE(raw.complete);
  CHECK(res.counts.points_done == 12);
  // Configuration 1 complete and right, configuration 2 up to n = 2, nothing after.
  for (int n = 0; n < 9; ++n)
    CHECK(raw.m_um[0][static_cast<std::size_t>(n)] == Approx(m.expected_um(0, n)).margin(1e-9));
  for (int n = 0; n < 3; ++n)
    CHECK(raw.m_um[1][static_cast<std::size_t>(n)] == Approx(m.expected_um(1, n)).margin(1e-9));
  for (std::size_t n = 3; n < 9; ++n)
    CHECK(std::isnan(raw.m_um[1][n]));
  for (std::size_t n = 0; n < 9; ++n)
    CHECK(std::isnan(raw.m_um[3][n]));

  // Written and read back: kept as a record, refused for separation.
  test::TempDir dir;
  io::write_raw_four_sensor_csv(dir / "raw.csv", raw);
  CHECK_THROWS_WITH(io::read_raw_four_sensor_csv(dir / "raw.csv"),
                    Catch::Contains("incomplete") && Catch::Contains("aborted"));
  io::RawReadOptions inspect;
  inspect.require_complete = false;
  const auto back = io::read_raw_four_sensor_csv(dir / "raw.csv", inspect);
  CHECK(back.m_um[1][2] == Approx(m.expected_um(1, 2)).margin(1e-9));
  CHECK(back.meta("points") == std::optional<std::string>("12 of 36"));
}

TEST_CASE("a sensor that stops answering: clear error naming it, stages stopped, incomplete") {
  FakeMachine m;
  FakeSensorFaults dead;
  dead.fail_from_read = 400;  // dies during the scan, for good
  dead.fail_status = IoStatus::timeout;
  m.add_single(dead);
  auto opts = m.options();
  opts.max_errors_per_point = 4;
  opts.point_retries = 2;
  const auto res = run_scan(m.devices(), opts);
  INFO(res.brief_report());
  CHECK(res.outcome == ScanRunOutcome::failed);
  CHECK_THAT(res.stop_reason, Catch::Contains("sensor 'sensor1'") && Catch::Contains("timeout") &&
                                  Catch::Contains("after 2 retries"));
  CHECK(res.counts.point_retries == 2);
  CHECK(m.slide.stops() >= 1);
  CHECK_FALSE(res.four_sensor->complete);
  CHECK(res.counts.points_done > 0);
  CHECK(res.counts.points_done < 36);
  // What was measured before the failure is kept and right.
  CHECK(res.four_sensor->m_um[0][0] == Approx(m.expected_um(0, 0)).margin(1e-9));
  CHECK(res.counts.samples_consumed == res.counts.samples);
}

TEST_CASE("an out-of-range sensor fails the scan with the status named") {
  FakeMachine m;
  FakeSensorFaults oor;
  oor.fail_every_n = 1;  // every reading out of range
  oor.fail_status = IoStatus::out_of_range;
  m.add_single(oor);
  auto opts = m.options();
  opts.point_retries = 0;
  const auto res = run_scan(m.devices(), opts);
  CHECK(res.outcome == ScanRunOutcome::failed);
  CHECK_THAT(res.stop_reason, Catch::Contains("out_of_range"));
  CHECK(res.counts.points_done == 0);
  CHECK_FALSE(res.four_sensor->complete);
}

TEST_CASE("a drive fault on the slide fails the scan with the fault code") {
  FakeMachine m;
  FakeStageFaults f;
  f.fault_on_move = 5;
  FakeStage faulty("slide", 2000.0, 1ms, 0.0, f);
  faulty.configure();
  m.add_single();
  auto dev = m.devices();
  dev.slide = &faulty;
  const auto res = run_scan(dev, m.options());
  CHECK(res.outcome == ScanRunOutcome::failed);
  CHECK_THAT(res.stop_reason, Catch::Contains("stage 'slide'") && Catch::Contains("drive fault") &&
                                  Catch::Contains("0x2310"));
  CHECK(faulty.stops() >= 1);
  CHECK(res.counts.points_done == 4);
}

TEST_CASE("a stuck slide times out and is stopped") {
  FakeMachine m;
  FakeStageFaults f;
  f.stuck_on_move = 2;
  FakeStage stuck("slide", 2000.0, 1ms, 0.0, f);
  stuck.configure();
  m.add_single();
  auto dev = m.devices();
  dev.slide = &stuck;
  auto opts = m.options();
  opts.move_timeout_ms = 300;
  const auto res = run_scan(dev, opts);
  CHECK(res.outcome == ScanRunOutcome::failed);
  CHECK_THAT(res.stop_reason, Catch::Contains("not in position after 300 ms"));
  CHECK(stuck.stops() >= 1);
}

// The slide behind a link that drops at its `on_move`-th command: the next `down_calls` calls
// answer `disconnected` (as ModbusBus does until its supervisor has reconnected).  With
// `lose_command` the command itself is lost with the link, so only a repeated command moves.
class DroppingLinkStage final : public Stage {
 public:
  DroppingLinkStage(FakeStage& inner, std::uint64_t on_move, int down_calls, bool lose_command)
      : inner_(inner), on_move_(on_move), down_calls_(down_calls), lose_command_(lose_command) {}
  const std::string& name() const override { return inner_.name(); }
  void configure() override { inner_.configure(); }
  IoStatus move_to(double position_mm) override {
    if (down()) return IoStatus::disconnected;
    if (++moves_ == on_move_) {
      down_left_ = down_calls_;
      if (lose_command_) return IoStatus::disconnected;
    }
    return inner_.move_to(position_mm);
  }
  IoStatus position(double& position_mm) override {
    return down() ? IoStatus::disconnected : inner_.position(position_mm);
  }
  IoStatus wait_in_position(std::chrono::milliseconds timeout) override {
    return down() ? IoStatus::disconnected : inner_.wait_in_position(timeout);
  }
  IoStatus stop() noexcept override { return inner_.stop(); }
  IoStatus fault_code(unsigned& code) override { return inner_.fault_code(code); }

 private:
  bool down() {
    if (down_left_ <= 0) return false;
    --down_left_;
    return true;
  }
  FakeStage& inner_;
  std::uint64_t on_move_, moves_ = 0;
  int down_calls_, down_left_ = 0;
  bool lose_command_;
};

TEST_CASE("a stage link that drops mid-move is waited for, the target commanded again, counted") {
  for (const bool lose_command : {false, true}) {
    DYNAMIC_SECTION((lose_command ? "command lost with the link" : "link lost while moving")) {
      FakeMachine m;
      DroppingLinkStage slide(m.slide, 6, 3, lose_command);
      m.add_single();
      auto dev = m.devices();
      dev.slide = &slide;
      const auto res = run_scan(dev, m.options());
      INFO(res.brief_report());
      REQUIRE(res.complete());
      // Every call that found the link down: the lost command's own answer, then three.
      const int losses = lose_command ? 4 : 3;
      CHECK(res.counts.stage_link_waits == static_cast<std::uint64_t>(losses));
      CHECK_THAT(res.brief_report(),
                 Catch::Contains("stage link down or unanswered " + std::to_string(losses) + "x"));
      // Every average where the model says: the slide was where the runner thought it was.
      REQUIRE(res.four_sensor);
      const auto& raw = *res.four_sensor;
      CHECK(raw.complete);
      REQUIRE(raw.positions() == 9);
      for (int c = 0; c < 4; ++c)
        for (int n = 0; n < 9; ++n)
          CHECK(raw.m_um[static_cast<std::size_t>(c)][static_cast<std::size_t>(n)] ==
                Approx(m.expected_um(c, n)).margin(1e-9));
    }
  }
}

TEST_CASE("a stage link that stays down fails the scan at the move deadline, naming it") {
  FakeMachine m;
  DroppingLinkStage slide(m.slide, 3, 1 << 30, false);
  m.add_single();
  auto dev = m.devices();
  dev.slide = &slide;
  auto opts = m.options();
  opts.move_timeout_ms = 400;
  const auto res = run_scan(dev, opts);
  CHECK(res.outcome == ScanRunOutcome::failed);
  CHECK_THAT(res.stop_reason, Catch::Contains("stage 'slide'") &&
                                  Catch::Contains("not in position after 400 ms (link down)"));
  CHECK(res.counts.stage_link_waits >= 3);
}

TEST_CASE("hooks: every cell as it is measured, heartbeats while waiting, per-bus rates") {
  // The daemon keeps a scan's cells as they come (its checkpoints) and watches heartbeats; an
  // abort after 12 points must leave exactly the cells of the record, no more.
  FakeMachine m;
  m.add_single();
  std::atomic<bool> abort{false};
  std::array<std::vector<double>, 4> cells;
  for (auto& c : cells)
    c.assign(9, std::numeric_limits<double>::quiet_NaN());
  int n_cells = 0, beats = 0;
  ScanHooks hooks;
  hooks.abort = &abort;
  hooks.cell = [&](std::size_t col, std::size_t n, double v, double) {
    REQUIRE(col < 4);
    REQUIRE(n < 9);
    CHECK(std::isnan(cells[col][n]));  // each cell once
    cells[col][n] = v;
    ++n_cells;
  };
  hooks.heartbeat = [&] { ++beats; };
  hooks.progress = [&](const ScanProgress& p) {
    if (p.point == 12) abort = true;
  };
  ScanDevices dev = m.devices();
  dev.bus_rate_hz = {1000.0};  // the bus's own rate, not the options' 2000 Hz
  const auto res = run_scan(dev, m.options(), hooks);
  CHECK(res.outcome == ScanRunOutcome::aborted);
  CHECK(n_cells == 12);
  CHECK(beats >= 12);  // at least one per point, more while moving and settling
  const auto& raw = *res.four_sensor;
  for (std::size_t i = 0; i < 4; ++i)
    for (std::size_t n = 0; n < 9; ++n) {
      INFO("configuration " << i + 1 << ", n = " << n);
      if (std::isnan(raw.m_um[i][n]))
        CHECK(std::isnan(cells[i][n]));
      else
        CHECK(cells[i][n] == raw.m_um[i][n]);
    }
  REQUIRE(res.samplers.size() == 1);
  CHECK(raw.meta("sample_rate_hz_bus0") == std::optional<std::string>("1000"));
}

TEST_CASE("displacement scan: two passes, reference piece displaced by d in between") {
  FakeMachine m;
  auto w = [](double x) { return 0.5 * std::sin(x / 7.0); };
  auto r = [](double x) { return 0.2 * std::cos(x / 4.0); };
  auto mo = [](double x) { return 0.01 * x; };
  m.sensors.push_back(std::make_unique<FakeSensor>("workpiece", [&](std::int64_t) {
    return w(m.slide.position_now_mm()) + mo(m.slide.position_now_mm());
  }));
  m.sensors.push_back(std::make_unique<FakeSensor>("reference", [&](std::int64_t) {
    const double x = m.slide.position_now_mm();
    return r(x + m.reference.position_now_mm()) + mo(x);
  }));
  for (auto& s : m.sensors)
    s->configure();
  auto opts = m.options();
  opts.kind = ScanKind::displacement;
  opts.d_mm = 3.0;
  opts.displacement_points = 6;
  const auto res = run_scan(m.devices(), opts);
  INFO(res.brief_report());
  REQUIRE(res.complete());
  REQUIRE(res.displacement);
  const auto& raw = *res.displacement;
  CHECK(raw.d_mm == 3.0);
  for (std::size_t k = 0; k < 6; ++k) {
    const double x = 3.0 * static_cast<double>(k);
    CHECK(raw.x_mm[k] == x);
    CHECK(raw.s1_scan1_um[k] == Approx(w(x) + mo(x)).margin(1e-9));
    CHECK(raw.s2_scan1_um[k] == Approx(r(x) + mo(x)).margin(1e-9));
    CHECK(raw.s2_scan2_um[k] == Approx(r(x + 3.0) + mo(x)).margin(1e-9));
    CHECK(raw.s1_scan2_um[k] == Approx(w(x) + mo(x)).margin(1e-9));
  }
}

TEST_CASE("devices that do not fit the scan are refused before anything moves") {
  FakeMachine m;
  m.add_fixed();
  auto dev = m.devices();
  dev.sensors.pop_back();
  CHECK_THROWS_WITH(run_scan(dev, m.options()),
                    Catch::Contains("1 sensor") && Catch::Contains("got 3"));
  auto opts = m.options();
  opts.averages = 0;
  CHECK_THROWS_WITH(run_scan(m.devices(), opts), Catch::Contains("averages = 0"));
  CHECK(m.slide.moves() == 0);
}

// Issue 16 item 2: the scan runs the traverses of its plan in order (configuration, direction)
// and records each with its readings' times; m1..m4 hold each configuration's first traverse.
TEST_CASE("a reversed plan: each configuration forward and back, every traverse recorded") {
  FakeMachine m;
  m.add_single();
  auto o = m.options();
  o.plan = core::ScanSequenceKind::reversed;
  int calls = 0;
  ScanHooks hooks;
  hooks.progress = [&](const ScanProgress& p) {
    ++calls;
    CHECK(p.points_total == 72);
  };
  const auto res = run_scan(m.devices(), o, hooks);
  INFO(res.brief_report());
  REQUIRE(res.complete());
  CHECK(calls == 72);
  REQUIRE(res.four_sensor);
  const auto& raw = *res.four_sensor;
  REQUIRE(raw.sequence);
  const auto& q = *raw.sequence;
  CHECK(q.plan == "reversed");
  REQUIRE(q.traverses.size() == 8);
  for (std::size_t k = 0; k < 8; ++k) {
    INFO("traverse " << k + 1);
    const int c = q.traverses[k].configuration;
    CHECK(c == static_cast<int>(k / 2));
    const bool fwd = q.traverses[k].direction == core::TraverseDirection::forward;
    CHECK(fwd == (k % 2 == 0));
    for (int n = 0; n < 9; ++n)
      CHECK(q.m_um[k][static_cast<std::size_t>(n)] == Approx(m.expected_um(c, n)).margin(1e-9));
    // Forward reads x_0 first, backward x_{P-1} first; the recorded start is the first reading.
    CHECK((fwd ? q.t_s[k].front() < q.t_s[k].back() : q.t_s[k].front() > q.t_s[k].back()));
    CHECK(q.traverses[k].start_s == (fwd ? q.t_s[k].front() : q.t_s[k].back()));
    if (k > 0) CHECK(q.traverses[k].start_s > q.traverses[k - 1].start_s);
  }
  for (std::size_t c = 0; c < 4; ++c)
    CHECK(raw.m_um[c] == q.m_um[2 * c]);
  // The file round-trips and core reads the plan back.
  test::TempDir tmp;
  io::write_raw_four_sensor_csv(tmp / "raw.csv", raw);
  const auto back = io::read_raw_four_sensor_csv(tmp / "raw.csv");
  const auto [seq, mq] = io::scan_sequence_of(back);
  CHECK(seq.size() == 8);
  CHECK(seq.traverses[3].direction == core::TraverseDirection::backward);
  CHECK(mq.cols() == 8);
}

TEST_CASE("a plan other than single is refused for four fixed sensors") {
  FakeMachine m;
  m.add_fixed();
  auto o = m.options();
  o.plan = core::ScanSequenceKind::closing_pass;
  CHECK_THROWS_WITH(run_scan(m.devices(), o, {}), Catch::Contains("needs one sensor"));
}

// Issue 16 item 2: the rezeroed plan needs the sensor moved in its holder between its passes, a
// step no stage here performs: refused before anything moves, saying why and what to do instead.
TEST_CASE("the rezeroed plan is refused: its re-zeroing is a step by hand") {
  FakeMachine m;
  m.add_single();
  auto o = m.options();
  o.plan = core::ScanSequenceKind::rezeroed;
  std::string why;
  CHECK_FALSE(o.is_valid(&why));
  CHECK_THAT(why, Catch::Contains("rezeroed") && Catch::Contains("by hand"));
  CHECK_THROWS_WITH(run_scan(m.devices(), o, {}),
                    Catch::Contains("re-zeroed by hand") && Catch::Contains("simulate it"));
  CHECK(m.slide.moves() == 0);
}

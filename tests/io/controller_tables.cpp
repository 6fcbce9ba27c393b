// Every CNC format errsep writes, read back by an independent reader that interpolates as the
// controller does (tests/support/controller_tables.hpp), on scans that ran at slide_start_mm =
// 250: the right correction at the machine positions of the measurement, nothing outside, the
// axes named as configured.  LinuxCNC through a model of its HAL network and of motion's external
// offsets (the real LinuxCNC runs in tests/apps/linuxcnc_hal.cpp).
#include <catch2/catch.hpp>
#include <cmath>
#include <vector>

#include "errsep/core/compensation.hpp"
#include "errsep/io/cnc/compensation_export.hpp"
#include "errsep/io/cnc/compensation_format.hpp"
#include "support/controller_tables.hpp"
#include "support/support.hpp"

using namespace errsep;

namespace {

void measured(std::uint32_t seed, std::vector<double>* x, std::vector<double>* s,
              std::vector<double>* u) {
  test::random_straightness(seed, x, s, u);
}

const io::ExportedTable& table_of(const io::CompensationExport& e, io::CompensationFormat f) {
  for (const auto& t : e.tables)
    if (t.format == f) return t;
  FAIL("no table of format " << io::to_string(f));
  return e.tables.front();
}

const io::CncFile& file_of(const io::ExportedTable& t, const std::string& suffix) {
  for (const auto& f : t.files)
    if (f.name.size() >= suffix.size() &&
        f.name.compare(f.name.size() - suffix.size(), suffix.size(), suffix) == 0)
      return f;
  FAIL("no file *" << suffix);
  return t.files.front();
}

// The applied correction (um) against the measurement over [first, last] on a fine grid, and
// the largest |value| outside it.
struct Applied {
  double max_inside_um = 0, max_outside_um = 0;
};
Applied check_applied(const core::CompensationProfile& p,
                      const std::function<double(double)>& applied_um) {
  Applied a;
  for (double q = p.first_mm(); q <= p.last_mm(); q += 0.37)
    a.max_inside_um = std::max(a.max_inside_um, std::abs(applied_um(q) - p.at(q)));
  a.max_inside_um =
      std::max(a.max_inside_um, std::abs(applied_um(p.last_mm()) - p.at(p.last_mm())));
  for (double q : {-500.0, 0.0, 100.0, p.first_mm() - 0.5, p.last_mm() + 0.5, 700.0, 2000.0})
    a.max_outside_um = std::max(a.max_outside_um, std::abs(applied_um(q)));
  return a;
}

// LinuxCNC: the HAL file in the network model; the machine switched on at `on_mm`, then the
// input axis driven below the range, above it, and back, in steps of `step_mm` per servo period.
// Returns the largest |request - table(position one period before)| after the first period.
double linuxcnc_run(const std::string& hal_text, const core::CompensationProfile& p, double on_mm,
                    double step_mm, int* periods) {
  test::HalNetwork hal(hal_text);
  test::EoffsetMotion motion;
  motion.period(hal, on_mm, false);  // off at on_mm
  motion.period(hal, on_mm, true);   // machine on there
  double prev = on_mm, worst = 0;
  int n = 0;
  auto go = [&](double target) {
    while (std::abs(target - prev) > 1e-12) {
      const double next =
          prev + std::copysign(std::min(step_mm, std::abs(target - prev)), target - prev);
      motion.period(hal, next, true);
      // The request motion computed this period answers the position of the period before.
      worst = std::max(worst, std::abs(motion.request_mm * 1e3 - p.at(prev)));
      prev = next;
      ++n;
    }
  };
  motion.period(hal, prev, true);  // one period for the loop to answer the machine-on position
  go(p.first_mm() - 30);
  go(p.last_mm() + 30);
  go(p.first_mm() - 30);
  *periods = n;
  return worst;
}

}  // namespace

TEST_CASE(
    "slide_start_mm = 250: every format gives the right correction at 250..end, none outside") {
  int linuxcnc_runs = 0;
  double worst_ratio = 0;
  for (std::uint32_t seed = 1; seed <= 6; ++seed) {
    INFO("seed " << seed);
    std::vector<double> x, s, u;
    measured(seed, &x, &s, &u);
    core::MachineAxes axes;
    axes.slide_start_mm = 250;
    const auto p = core::compensation_profile(x, s, u, axes);
    REQUIRE(p.first_mm() == 250);
    REQUIRE(p.last_mm() == 555);
    io::CompensationExportOptions o;
    o.title = "seed " + std::to_string(seed);
    const auto e = io::export_compensation(p, o);
    REQUIRE(e.tables.size() == io::all_compensation_formats().size());
    CHECK(e.measurement_U_um == Approx(0.2));

    // Sinumerik CEC.
    {
      const auto& t = table_of(e, io::CompensationFormat::sinumerik_cec);
      const auto cec = test::parse_sinumerik_cec(t.files.front().content);
      CHECK(cec.has_header);
      CHECK(cec.has_m17);
      CHECK(cec.input_axis == "(AX1)");
      CHECK(cec.output_axis == "(AX2)");
      CHECK(cec.direction == 0);
      CHECK(cec.min_mm == 250);
      CHECK(cec.max_mm == 555);
      CHECK(cec.values_mm.size() <= 200);
      const auto a = check_applied(p, [&](double q) { return 1e3 * cec.apply_mm(q); });
      CHECK(a.max_inside_um <= t.accuracy.max_um + 1e-9);
      CHECK(t.accuracy.max_um <= 0.001);  // the samples themselves, 1 nm values
      CHECK(a.max_outside_um <= 1e-9);
      CHECK_THAT(t.files.front().content, Catch::Contains("interpolation error"));
    }
    // Beckhoff.
    {
      const auto& t = table_of(e, io::CompensationFormat::beckhoff_crosscomp);
      const auto l = test::parse_beckhoff_crosscomp(t.files.front().content);
      CHECK(l.axis_number == 2);
      CHECK(l.master_axis_number == 1);
      CHECK(l.axis_name == "Y");
      CHECK(l.setpoint_mm.front() == 250);
      CHECK(l.setpoint_mm.back() == 555);
      const auto a = check_applied(p, [&](double q) { return 1e3 * l.apply_mm(q); });
      CHECK(a.max_inside_um <= t.accuracy.max_um + 1e-9);
      CHECK(t.accuracy.max_um <= 0.05 + 1e-9);  // 0.1 um units, rounded
      CHECK(a.max_outside_um <= 1e-9);
    }
    // HEIDENHAIN.
    {
      const auto& t = table_of(e, io::CompensationFormat::heidenhain_com);
      const auto com = test::parse_heidenhain_com(file_of(t, ".COM").content);
      const auto cma = test::parse_heidenhain_cma(file_of(t, ".CMA").content);
      CHECK(file_of(t, ".COM").name == "EYX.COM");
      CHECK(com.axis == 'Y');  // the compensated axis's column: Y = F(X), ISO 230-1 EYX
      CHECK(cma.column == "X");
      CHECK(cma.com_path == "TNC:\\table\\EYX.COM");
      CHECK(cma.active);
      CHECK(com.axispos_mm.front() == 250);
      CHECK(com.axispos_mm.back() == 555);
      CHECK(com.axispos_mm.size() <= 256);
      const auto a = check_applied(p, [&](double q) { return 1e3 * com.apply_mm(q); });
      CHECK(a.max_inside_um <= t.accuracy.max_um + 1e-9);
      CHECK(t.accuracy.max_um <= 0.05 + 1e-9);  // 4 decimals of mm
      CHECK(a.max_outside_um <= 1e-9);
    }
    // errsep CSV.
    {
      const auto& t = table_of(e, io::CompensationFormat::csv);
      const auto c = test::parse_comp_csv(t.files.front().content);
      CHECK(c.meta.at("input_axis") == "X");
      CHECK(c.meta.at("output_axis") == "Y");
      CHECK(c.x_mm.front() == 250);
      CHECK(c.x_mm.back() == 555);
      const auto a = check_applied(p, [&](double q) { return c.apply_um(q); });
      CHECK(a.max_inside_um <= t.accuracy.max_um + 1e-9);
      CHECK(a.max_outside_um <= 1e-9);
    }
    // LinuxCNC: the HAL network, from three machine-on positions (below, inside, above the
    // range), both directions.
    {
      const auto& t = table_of(e, io::CompensationFormat::linuxcnc_hal);
      const std::string& text = t.files.front().content;
      test::HalNetwork hal(text);
      const auto curves = hal.lincurves();
      // 62 samples in the default 64 points: every sample, in 5 chained lincurves of <= 16.
      REQUIRE(curves.size() == 5);
      double lo = 1e9, hi = -1e9;
      for (const auto& [name, points] : curves) {
        CHECK(points <= 16);
        const auto xs = hal.lincurve_points(name, 'x');
        lo = std::min(lo, xs.front());
        hi = std::max(hi, xs.back());
        CHECK(hal.source_of(name + ".in") == "axis.x.pos-cmd");
      }
      CHECK(lo == 250);
      CHECK(hi == 555);
      CHECK(t.accuracy.max_um <= 0.0021);  // the samples themselves, 1 nm values + 2 counts
      CHECK(hal.connected("axis.y.eoffset-counts"));
      CHECK(hal.connected("axis.y.eoffset-request"));
      for (const double on : {100.0, 400.0, 700.0}) {
        int periods = 0;
        const double worst = linuxcnc_run(text, p, on, 0.2, &periods);
        INFO("machine on at " << on << " mm, " << periods << " periods");
        CHECK(periods > 4000);
        CHECK(worst <= t.accuracy.max_um + 1e-9);
        worst_ratio = std::max(worst_ratio, worst / t.accuracy.max_um);
        ++linuxcnc_runs;
      }
    }
  }
  WARN("LinuxCNC HAL model: " << linuxcnc_runs
                              << " runs; largest |request - measured compensation| / stated "
                                 "interpolation error = "
                              << worst_ratio);
}

TEST_CASE("LinuxCNC: lincurve fed straight into eoffset-counts shifts by its machine-on value") {
  // Why the HAL file feeds the request back: the obvious arrangement, in the same model, is off
  // by the table's value where the machine was switched on.
  std::vector<double> x, s, u;
  measured(3, &x, &s, &u);
  core::MachineAxes axes;
  axes.slide_start_mm = 250;
  const auto p = core::compensation_profile(x, s, u, axes);
  const auto t = core::make_breakpoint_table(p);
  std::string naive = "loadrt lincurve names=lc personality=" + std::to_string(t.points()) +
                      "\nloadrt conv_float_s32 names=lcs\naddf lc servo-thread\naddf lcs "
                      "servo-thread\n";
  for (std::size_t i = 0; i < t.points(); ++i) {
    char line[128];
    std::snprintf(line, sizeof line, "setp lc.x-val-%02zu %.6f\nsetp lc.y-val-%02zu %.3f\n", i,
                  t.position_mm[i], i, t.comp_um[i] * 1e3);
    naive += line;
  }
  naive +=
      "net pos axis.x.pos-cmd => lc.in\nnet cf lc.out => lcs.in\nnet cnt lcs.out => "
      "axis.y.eoffset-counts\nsetp axis.y.eoffset-scale 1e-06\nsetp axis.y.eoffset-enable 1\n";
  const double on = 400;
  int periods = 0;
  const double worst = linuxcnc_run(naive, p, on, 0.2, &periods);
  // Off by lincurve(400) everywhere; lincurve is within its interpolation error of the table.
  const double expected = std::abs(p.at(on)) - core::table_accuracy(p, t).max_um;
  WARN("naive arrangement, machine on at 400 mm: worst error "
       << worst << " um, table(400) = " << p.at(on) << " um");
  CHECK(expected > 0.5);
  CHECK(worst >= expected);
}

TEST_CASE("the format registry: names beside the enum, suffixes, any format read back") {
  for (const auto f : io::all_compensation_formats()) {
    CHECK(io::parse_compensation_format(io::to_string(f)) == f);
    const auto& w = io::compensation_writer(f);
    CHECK(w.format() == f);
    CHECK(io::compensation_format_of(std::string("T") + w.suffix()) == f);
    CHECK_FALSE(w.parameters().empty());
  }
  CHECK_FALSE(io::parse_compensation_format("fanuc").has_value());
  CHECK_THAT(io::compensation_format_names(), Catch::Contains("heidenhain_com"));
  CHECK(io::compensation_format_of("x.com") == io::CompensationFormat::heidenhain_com);

  // Every file errsep writes is read back by read_compensation_file as what was written.
  std::vector<double> x, s, u;
  measured(11, &x, &s, &u);
  core::MachineAxes axes;
  axes.slide_start_mm = 250;
  axes.output_axis = 'Z';
  const auto p = core::compensation_profile(x, s, u, axes);
  const auto e = io::export_compensation(p, {});
  test::TempDir tmp;
  const auto written = io::write_compensation_export(tmp / "comp", e);
  CHECK(std::filesystem::exists(tmp / "comp" / "accuracy.csv"));
  for (const auto& t : e.tables) {
    const auto back = io::read_compensation_file(tmp / "comp" / t.files.front().name);
    CHECK(back.table.position_mm == t.read_back.table.position_mm);
    CHECK(back.table.comp_um == t.read_back.table.comp_um);
    if (back.output_axis) CHECK(back.output_axis == 'Z');
  }
  CHECK_THROWS_WITH(io::read_compensation_file(tmp / "comp" / "x.txt"),
                    Catch::Contains("not a compensation table") && Catch::Contains(".COM"));
}

TEST_CASE("writers refuse bad parameters and tables they cannot hold, naming them") {
  std::vector<double> x, s, u;
  measured(2, &x, &s, &u);
  const auto p = core::compensation_profile(x, s, u, core::MachineAxes{});
  auto expect = [&](io::CompensationFormat f, io::CncParameters params, const std::string& msg) {
    io::CompensationExportOptions o;
    o.formats = {f};
    o.parameters[f] = std::move(params);
    CHECK_THROWS_WITH(io::export_compensation(p, o), Catch::Contains(msg));
  };
  using F = io::CompensationFormat;
  expect(F::sinumerik_cec, {{"input_axis", "X 1"}}, "sinumerik_cec.input_axis");
  expect(F::sinumerik_cec, {{"output_axis", "AX1"}}, "equals input_axis");
  expect(F::sinumerik_cec, {{"direction", "2"}}, "sinumerik_cec.direction: 2 is out of range");
  expect(F::sinumerik_cec, {{"max_points", "10"}, {"step_mm", "5"}}, "limit of 10");
  expect(F::sinumerik_cec, {{"colour", "red"}}, "sinumerik_cec.colour: unknown parameter");
  expect(F::linuxcnc_hal, {{"points", "300"}}, "linuxcnc_hal.points: 300 is out of range 2..241");
  expect(F::linuxcnc_hal, {{"input_pin", "axis x"}}, "is not a HAL name");
  expect(F::beckhoff_crosscomp, {{"master_axis", "2"}}, "equals axis");
  expect(F::heidenhain_com, {{"step_mm", "10"}}, "does not divide");
  expect(F::csv, {{"max_points", "1"}}, "at least 2 points");
  // A title with a newline cannot inject a line into the NC program.
  io::CompensationExportOptions o;
  o.formats = {F::sinumerik_cec};
  o.title = "scan 1\n$AN_CEC[0,0]=5";
  const auto e = io::export_compensation(p, o);
  const auto cec = test::parse_sinumerik_cec(e.tables.front().files.front().content);
  CHECK(cec.values_mm.at(0) == 0);
}

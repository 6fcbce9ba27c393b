// Each controller table, read back by an independent reader that interpolates as the controller
// does (tests/support/controller_tables.hpp), is applied to a simulated slideway; the residual
// straightness must fall below a stated fraction of the original.
#include "errsep/io/controller_tables.hpp"

#include <catch2/catch.hpp>
#include <cmath>
#include <functional>
#include <random>
#include <vector>

#include "errsep/core/compensation.hpp"
#include "errsep/core/iso230.hpp"
#include "support/controller_tables.hpp"

using namespace errsep;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kTravel = 305;  // Zhao et al. 2019, section 3: L = 305 mm, dx = 5 mm

// The simulated slideway: Zhao 2019 Eq. (21) plus an alignment offset and tilt, in um.
double true_error_um(double x) {
  const double L = kTravel;
  return 8.075 * std::sin(4 * kPi / L * x) + 5.7 * std::sin(6 * kPi / L * x + 5 * kPi / 18) -
         1.9 * std::sin(14 * kPi / L * x + kPi / 2) + 2.0 + 0.012 * x;
}

// The measurement: every 5 mm with Gaussian noise of 0.1 um (the paper's smallest sigma).
void measure(std::vector<double>* x, std::vector<double>* s) {
  std::mt19937 rng(2019);
  std::normal_distribution<double> nd(0, 0.1);
  for (int i = 0; i * 5.0 <= kTravel + 1e-9; ++i) {
    x->push_back(i * 5.0);
    s->push_back(true_error_um(i * 5.0) + nd(rng));
  }
}

struct Residual {
  double original_um = 0, residual_um = 0, flipped_um = 0;
};

// Residual straightness (minimum zone) over a 0.1 mm grid when the controller adds comp(x) (mm)
// to the commanded position: actual - commanded = error + comp.
Residual apply(const std::function<double(double)>& comp_mm) {
  std::vector<double> x, e, r, f;
  for (int i = 0; i * 0.1 <= kTravel + 1e-9; ++i) {
    const double xi = i * 0.1;
    x.push_back(xi);
    e.push_back(true_error_um(xi));
    r.push_back(true_error_um(xi) + 1e3 * comp_mm(xi));
    f.push_back(true_error_um(xi) - 1e3 * comp_mm(xi));  // wrong sign: must get worse
  }
  const auto mz = core::ReferenceLine::minimum_zone;
  Residual out;
  out.original_um = core::evaluate_straightness(x, e, {}, mz).straightness_um;
  out.residual_um = core::evaluate_straightness(x, r, {}, mz).straightness_um;
  out.flipped_um = core::evaluate_straightness(x, f, {}, mz).straightness_um;
  return out;
}

}  // namespace

// Stated fractions, from an a-priori bound: linear interpolation of A sin(kx) with step h is off by
// at most A (kh)^2 / 8; over the three harmonics of Eq. (21) that is 0.23 um at h = 5 mm and
// 0.94 um at h = 10 mm.  The residual zone is at most twice that plus the measurement noise
// (about +-3 sigma = 0.6 um): 1.1 um (4.4 % of the 24.6 um original) at 5 mm, 2.5 um (10 %) at
// 10 mm.  Hence 5 % and 10 %.
TEST_CASE("Sinumerik CEC table: residual straightness below 5 % (5 mm) / 10 % (10 mm)") {
  std::vector<double> x, s;
  measure(&x, &s);
  for (const auto& [step, fraction] : {std::pair{5.0, 0.05}, std::pair{10.0, 0.10}}) {
    INFO("step " << step << " mm");
    core::CompensationOptions co;
    co.step_mm = step;
    const auto table = core::make_uniform_table(x, s, co);
    io::SinumerikCecOptions so;
    so.table_index = 2;
    so.input_axis = "X1";
    so.output_axis = "Y1";
    const std::string text = io::format_sinumerik_cec(table, so);
    const auto cec = test::parse_sinumerik_cec(text, 2);
    CHECK(cec.has_header);
    CHECK(cec.has_m17);
    CHECK(cec.input_axis == "(X1)");
    CHECK(cec.output_axis == "(Y1)");
    CHECK(cec.direction == 0);
    CHECK(cec.is_modulo == 0);
    CHECK(cec.min_mm == 0);
    CHECK(cec.max_mm >= kTravel);
    const auto r = apply([&](double xi) { return cec.apply_mm(xi); });
    WARN("CEC step " << step << " mm: original " << r.original_um << " um, residual "
                     << r.residual_um << " um (" << 100 * r.residual_um / r.original_um << " %)");
    CHECK(r.original_um > 20);  // the simulated slideway is what we think it is
    CHECK(r.residual_um < fraction * r.original_um);
    CHECK(r.flipped_um > 1.5 * r.original_um);
  }
}

// lincurve: 16 points chosen by core::make_breakpoint_table; its reported max interpolation error
// (about 1 um here, noise included) bounds the residual zone by twice that: 10 % is stated.
TEST_CASE("LinuxCNC lincurve HAL: residual straightness below 10 % of the original") {
  std::vector<double> x, s;
  measure(&x, &s);
  const auto table = core::make_breakpoint_table(x, s, {});
  io::LinuxCncLincurveOptions lo;
  lo.instance = "eyx-comp";
  lo.input_pin = "axis.x.pos-cmd";
  lo.output_axis = 'Y';
  const std::string text = io::format_linuxcnc_lincurve_hal(table, lo);
  const auto hal = test::parse_lincurve_hal(text);
  CHECK(hal.personality == table.x_mm.size());
  CHECK(hal.personality <= 16);
  CHECK(hal.input_pin == "axis.x.pos-cmd");
  CHECK(hal.output_pin == "axis.y.eoffset-counts");
  CHECK(hal.enabled);
  CHECK(hal.eoffset_scale == Approx(1e-6));
  const auto r = apply([&](double xi) { return hal.apply_mm(xi); });
  WARN("lincurve " << hal.personality << " points: original " << r.original_um << " um, residual "
                   << r.residual_um << " um (" << 100 * r.residual_um / r.original_um
                   << " %), max interpolation error " << table.max_interpolation_error_um << " um");
  CHECK(r.residual_um < 0.10 * r.original_um);
  CHECK(r.flipped_um > 1.5 * r.original_um);
  // The file states its interpolation error.
  CHECK_THAT(text, Catch::Contains("interpolation error"));
}

// Beckhoff at 5 mm: as the CEC table, plus rounding to 0.1 um (+-0.05 um): 5 %.
TEST_CASE("Beckhoff cross compensation list: residual straightness below 5 % of the original") {
  std::vector<double> x, s;
  measure(&x, &s);
  core::CompensationOptions co;
  co.step_mm = 5;
  const auto table = core::make_uniform_table(x, s, co);
  io::BeckhoffCrosscompOptions bo;
  bo.axis_number = 2;
  bo.axis_name = "Y";
  bo.master_axis_number = 1;
  const auto list = test::parse_beckhoff_crosscomp(io::format_beckhoff_crosscomp(table, bo));
  CHECK(list.axis_number == 2);
  CHECK(list.master_axis_number == 1);
  CHECK(list.axis_name == "Y");
  CHECK(list.setpoint_mm.size() == table.comp_um.size());
  const auto r = apply([&](double xi) { return list.apply_mm(xi); });
  WARN("crosscomp: original " << r.original_um << " um, residual " << r.residual_um << " um ("
                              << 100 * r.residual_um / r.original_um << " %)");
  CHECK(r.residual_um < 0.05 * r.original_um);
  CHECK(r.flipped_um > 1.5 * r.original_um);
}

TEST_CASE("writers refuse bad options and tables") {
  core::UniformCompensationTable t;
  t.start_mm = 0;
  t.step_mm = 10;
  t.comp_um = {0, 1, 2};
  io::SinumerikCecOptions so;
  so.output_axis = so.input_axis;
  CHECK_THROWS_WITH(io::format_sinumerik_cec(t, so), Catch::Contains("both"));
  so = {};
  so.direction = 2;
  CHECK_THROWS_WITH(io::format_sinumerik_cec(t, so), Catch::Contains("direction"));
  core::BreakpointTable b;
  for (int i = 0; i < 17; ++i)
    b.x_mm.push_back(i), b.comp_um.push_back(0);
  CHECK_THROWS_WITH(io::format_linuxcnc_lincurve_hal(b, {}), Catch::Contains("at most 16"));
  io::BeckhoffCrosscompOptions bo;
  bo.master_axis_number = bo.axis_number;
  CHECK_THROWS_WITH(io::format_beckhoff_crosscomp(t, bo), Catch::Contains("master_axis_number"));
  // A title with a newline cannot inject a line into the NC program.
  so = {};
  so.title = "scan 1\n$AN_CEC[0,0]=5";
  const std::string text = io::format_sinumerik_cec(t, so);
  CHECK_NOTHROW(test::parse_sinumerik_cec(text));
  CHECK(test::parse_sinumerik_cec(text).values_mm.at(0) == 0);
}

// errsep-separate-displacement: the displacement method (Haramiishi et al. 2024), one axis and
// two axes with roll/pitch correction, and the generalised three-point method, on recorded CSV.
// Parse, call the library, report; every result is computed before anything is written, and
// written atomically.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <iostream>
#include <optional>

#include "errsep/core/displacement_method.hpp"
#include "errsep/core/three_point_method.hpp"
#include "errsep/core/two_axis_displacement.hpp"
#include "errsep/io/displacement_csv.hpp"
#include "errsep/version.hpp"

namespace {

constexpr const char* kColumns =
    R"(Input CSV (errsep convention: "# key: value" metadata lines, one header, numeric rows;
sN_scanK_um = sensor N, scan K, as in the raw-scan CSV that errsep-scan records):
  one-axis     a raw displacement scan ("# format: errsep raw displacement scan", "# d_mm: d"),
               or any CSV with x_mm, s1_scan1_um, s2_scan1_um, s2_scan2_um [+ "# d_mm: d"]
               s1 = workpiece sensor, s2 = reference sensor; scan 2 after the reference piece is
               traversed by d.  x uniform and increasing.  d: --d-mm, else d_mm, else dx.
  two-axis     x_mm, y_mm, s0_scan1_um, s1_scan1_um, s1_scan2_um, s2_scan1_um, s2_scan2_um,
               s3_scan1_um, s3_scan2_um, s4_scan1_um, s4_scan2_um   (one row per grid point,
               any order, every point of a uniform x-y grid exactly once)
  three-point  x_mm, m1_um, m2_um, m3_um   (sensors at 0, s1*dx, (s1+s2)*dx on the carriage)
Output CSV:
  one-axis     x_mm, r_um, m_um, w_um
  two-axis     x_mm, y_mm, w_um, m_w_um, m1x_um, m2x_um, m3y_um, m4y_um, m_wxe_um, m_wye_um,
               r1x_um, r2x_um, r3y_um, r4y_um   (x fastest)
  three-point  x_mm, f_um; with --motion-out also x_mm, S_um, gamma_urad
d must be an integer multiple of the sampling interval.  Exit status 0 on success, 1 on bad input
(message "file:line: problem"), nothing written on failure.)";

errsep::core::ChainJoin chain_join_from(const std::string& s) {
  return s == "given" ? errsep::core::ChainJoin::given_initial_values
                      : errsep::core::ChainJoin::least_roughness;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "errsep displacement-method separation (Haramiishi et al. 2024): workpiece profile, "
      "reference profiles and table motion error from two scans; also the generalised "
      "three-point method"};
  app.set_version_flag("--version", std::string(errsep::kVersion));
  app.footer(kColumns);
  app.require_subcommand(1);

  std::string input, output, motion_out, chain = "least-roughness";
  std::optional<double> d_mm, d_x_mm, d_y_mm;
  double r0_um = 0;
  errsep::core::TwoAxisGeometry geo;
  bool no_rotation = false;
  int s1 = 1, s2 = 1;

  auto* one = app.add_subcommand("one-axis", "one-axis displacement method, Eqs. (1)-(9)");
  auto* two =
      app.add_subcommand("two-axis", "x-y stage with roll/pitch correction, Eqs. (10)-(27)");
  auto* three = app.add_subcommand("three-point", "generalised three-point method");
  for (auto* sc : {one, two, three}) {
    sc->add_option("-i,--input", input, "recorded scans (CSV, columns in --help)")->required();
    sc->add_option("-o,--out", output, "result CSV (written atomically)")->required();
  }
  for (auto* sc : {one, two})
    sc->add_option("--chain-join", chain,
                   "d > dx: join the d/dx chains by least-roughness or take given initial values")
        ->check(CLI::IsMember({"least-roughness", "given"}));
  one->add_option(
      "--d-mm", d_mm,
      "traverse d of the reference piece (default: the file's d_mm, else the sampling interval)");
  one->add_option("--r0-um", r0_um, "initial value r(x_1) of Eq. (9) (default 0)");
  two->add_option("--d-x-mm", d_x_mm, "traverse of reference piece X (default: x interval)");
  two->add_option("--d-y-mm", d_y_mm, "traverse of reference piece Y (default: y interval)");
  two->add_option("--l-xs-mm", geo.l_xs_mm, "distance sensor 1 to sensor 2")->capture_default_str();
  two->add_option("--l-xw-mm", geo.l_xw_mm, "sensor 2 to sensor 0, positive toward sensor 1")
      ->capture_default_str();
  two->add_option("--l-ys-mm", geo.l_ys_mm, "distance sensor 3 to sensor 4")->capture_default_str();
  two->add_option("--l-yw-mm", geo.l_yw_mm,
                  "sensor 4 to sensor 0 at the first x, positive toward sensor 3")
      ->capture_default_str();
  two->add_option("--l-yw-per-x", geo.l_yw_per_x,
                  "change of l_yw per mm of x travel (0 = paper; -1 or +1 when sensor 0 is on "
                  "the base and sensors 3, 4 ride on the x table)")
      ->capture_default_str();
  two->add_flag("--no-rotation-correction", no_rotation,
                "use Eqs. (20)-(21) (m_w = m2_x + m4_y) instead of (22)-(27)");
  three->add_option("--s1", s1, "spacing sensor 1 -> 2 in sampling intervals")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  three->add_option("--s2", s2, "spacing sensor 2 -> 3 in sampling intervals")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  three->add_option("--motion-out", motion_out, "also write straightness and tilt (CSV)");
  CLI11_PARSE(app, argc, argv);

  try {
    if (one->parsed()) {
      const auto in = errsep::io::read_one_axis_csv(input);
      errsep::core::DisplacementOptions o;
      o.sample_interval_mm = in.dx_mm;
      if (d_mm && in.d_mm && std::abs(*d_mm - *in.d_mm) > 1e-9 * std::max(1.0, *d_mm))
        throw std::invalid_argument(input + ": --d-mm " + std::to_string(*d_mm) +
                                    " contradicts the file's d_mm " + std::to_string(*in.d_mm));
      o.displacement_mm = d_mm ? *d_mm : in.d_mm.value_or(in.dx_mm);
      o.initial_um = r0_um;
      o.chain_join = chain_join_from(chain);
      std::string why;
      if (!o.is_valid(&why)) throw std::invalid_argument(input + ": " + why);
      const auto res = errsep::core::separate_displacement(in.s1_1_um, in.s2_1_um, in.s2_2_um, o);
      errsep::io::write_csv(output, errsep::io::one_axis_result_csv(in.x_mm, res));
      std::cout << res.brief_report() << "\nwrote " << output << "\n";
    } else if (two->parsed()) {
      const auto in = errsep::io::read_two_axis_csv(input);
      errsep::core::TwoAxisOptions o;
      o.dx_mm = in.dx_mm;
      o.dy_mm = in.dy_mm;
      o.displacement_x_mm = d_x_mm.value_or(in.dx_mm);
      o.displacement_y_mm = d_y_mm.value_or(in.dy_mm);
      o.geometry = geo;
      o.correct_rotation = !no_rotation;
      o.chain_join = chain_join_from(chain);
      std::string why;
      if (!o.is_valid(&why)) throw std::invalid_argument(input + ": " + why);
      const auto res = errsep::core::separate_two_axis(in.scan, o);
      errsep::io::write_csv(output, errsep::io::two_axis_result_csv(in.scan, res));
      std::cout << res.brief_report() << "\nwrote " << output << "\n";
    } else {
      const auto in = errsep::io::read_three_point_csv(input);
      errsep::core::ThreePointOptions o;
      o.s1 = s1;
      o.s2 = s2;
      o.sample_interval_mm = in.dx_mm;
      const auto res = errsep::core::separate_three_point(in.m_um, o);
      const auto profile = errsep::io::three_point_profile_csv(in.x_mm(0), in.dx_mm, res);
      const auto motion = errsep::io::three_point_motion_csv(in.x_mm, res);
      errsep::io::write_csv(output, profile);
      if (!motion_out.empty()) errsep::io::write_csv(motion_out, motion);
      std::cout << res.brief_report() << "\nwrote " << output
                << (motion_out.empty() ? "" : " and " + motion_out) << "\n";
    }
  } catch (const std::exception& e) {
    std::cerr << "errsep-separate-displacement: " << e.what() << "\n";
    return 1;
  }
  return 0;
}

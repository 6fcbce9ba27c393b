// errsep-plan: proposes a four-sensor scan (spacings s2, s3, s4, N, dx, samples per point K) that
// reaches a target uncertainty of the straightness, predicted before measuring
// (core/scan_plan.hpp), or predicts one given configuration; prints the proposal and writes
// plan.csv (predicted u_S(x)), scan.toml (the [scan] keys for the machine config), plan.txt and
// the figure u_S.png/svg.
#include <CLI/CLI.hpp>
#include <cmath>
#include <exception>
#include <iostream>

#include "errsep/core/scan_plan.hpp"
#include "errsep/io/scan_plan_report.hpp"
#include "errsep/version.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "errsep-plan: a four-sensor scan plan for a target straightness uncertainty U, predicted "
      "before measuring from the geometry and the noise alone"};
  app.set_version_flag("--version", std::string(errsep::kVersion));
  errsep::core::ScanPlanOptions o;
  std::vector<double> dx_range;
  std::vector<int> spacings;
  int averages = 1;
  std::string out;
  bool no_plot = false;
  app.add_option("--travel-mm", o.travel_mm, "slide travel L to measure")->capture_default_str();
  app.add_option("--dx-mm", o.dx_mm, "sampling interval(s) to consider")->capture_default_str();
  app.add_option("--dx-range-mm", dx_range, "sampling intervals MIN MAX STEP (instead of --dx-mm)")
      ->expected(3);
  app.add_option("--stage-range-mm", o.stage.range_mm,
                 "largest sensor offset D2+D3+D4 the sensor stage reaches")
      ->capture_default_str();
  app.add_option("--stage-step-mm", o.stage.step_mm,
                 "offsets must be multiples of this (stage resolution or detents; 0 = any)")
      ->capture_default_str();
  app.add_option("--stage-positions-mm", o.stage.positions_mm,
                 "the only positions the sensor stage can take (instead of range and step)");
  app.add_option("--reference-max-mm", o.reference_length_max_mm,
                 "longest reference surface L + D2+D3+D4 (0 = no limit)")
      ->capture_default_str();
  app.add_option("--sigma-um", o.sigma_um, "noise of one sensor sample (standard deviation)")
      ->capture_default_str();
  app.add_option("--target-U-um", o.target_U_um, "target expanded uncertainty of the straightness")
      ->capture_default_str();
  app.add_option("--averages-max", o.averages_max, "most samples per point K")
      ->capture_default_str();
  app.add_option("-k,--coverage-factor", o.coverage_factor, "k of U = k*u")->capture_default_str();
  app.add_option("--max-evaluations", o.max_evaluations,
                 "most configurations predicted (beyond: a sampled search)")
      ->capture_default_str();
  app.add_option("--spacings", spacings,
                 "predict this configuration S2 S3 S4 only (no search; first --dx-mm)")
      ->expected(3);
  app.add_option("--averages", averages, "with --spacings: samples per point K")
      ->capture_default_str();
  app.add_option("-o,--out", out, "write plan.csv, scan.toml, plan.txt and u_S.png/svg here");
  app.add_flag("--no-plot", no_plot, "do not draw the figure (gnuplot)");
  app.footer(
      "Predicted U = k*sqrt(2*mean_x u_d(x)^2), u_d the standard uncertainty of S about its\n"
      "least-squares line (the rms over the pairs of positions that may hold the extremes).\n"
      "Exit status: 0 plan meets the target, 2 it does not (the best reachable is written),\n"
      "1 bad options.");
  CLI11_PARSE(app, argc, argv);
  try {
    if (!dx_range.empty()) {
      if (!(dx_range[0] > 0 && dx_range[1] >= dx_range[0] && dx_range[2] > 0))
        throw std::invalid_argument("--dx-range-mm: need 0 < MIN <= MAX and STEP > 0");
      o.dx_mm.clear();
      for (double dx = dx_range[0]; dx <= dx_range[1] * (1 + 1e-12); dx += dx_range[2])
        o.dx_mm.push_back(dx);
    }
    errsep::core::ScanPlan plan;
    if (!spacings.empty()) {
      std::string why;
      if (!o.is_valid(&why)) throw std::invalid_argument(why);
      const double dx = o.dx_mm.front();
      const double steps = o.travel_mm / dx;
      const int T = spacings[0] + spacings[1] + spacings[2];
      const errsep::core::FourSensorConfig cfg{dx, spacings[0], spacings[1], spacings[2],
                                               static_cast<int>(std::lround(steps)) + 1 + T};
      if (std::abs(steps - std::round(steps)) > 1e-6 * steps)
        throw std::invalid_argument("--travel-mm " + std::to_string(o.travel_mm) +
                                    " is not a whole number of --dx-mm " + std::to_string(dx));
      plan = errsep::core::evaluate_scan_configuration(cfg, o.sigma_um, averages, o.target_U_um,
                                                       o.coverage_factor);
    } else {
      plan = errsep::core::plan_four_sensor_scan(o);
    }
    const bool with_origin = !o.stage.positions_mm.empty();
    std::cout << errsep::io::scan_plan_summary(plan) << "\n"
              << errsep::io::scan_plan_toml(plan, with_origin);
    if (!out.empty()) {
      std::optional<errsep::io::PlotOptions> plot;
      if (!no_plot) {
        if (errsep::io::gnuplot_available())
          plot = errsep::io::PlotOptions{};
        else
          std::cerr << "errsep-plan: gnuplot not found: no figure (install gnuplot-nox)\n";
      }
      errsep::io::write_scan_plan(plan, out, with_origin, plot);
    }
    return plan.target_met ? 0 : 2;
  } catch (const std::exception& e) {
    std::cerr << "errsep-plan: " << e.what() << "\n";
    return 1;
  }
}

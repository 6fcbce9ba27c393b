// errsep-report: turns a result directory (errsep-separate / errsep-simulate --out, or a
// displacement-method grid CSV) into the ISO 230-1 evaluation (evaluation.csv, evaluation.txt),
// figures (plots/), a self-contained report.html and compensation tables (compensation/).
#include <CLI/CLI.hpp>
#include <exception>
#include <iostream>
#include <map>

#include "errsep/io/scan_report.hpp"
#include "errsep/io/staged_directory.hpp"
#include "errsep/version.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "errsep report: ISO 230-1 evaluation, plots, HTML report and CNC compensation tables "
      "for a result directory"};
  app.set_version_flag("--version", std::string(errsep::kVersion));
  std::string dir;
  errsep::io::ScanReportOptions o;
  std::string axis, direction, correlation = "bound", local_ref = "least_squares",
                               remove_line = "end_points";
  std::string grid;
  bool no_plots = false, no_tables = false, invert = false;
  app.add_option("dir", dir, "result directory (motion.csv, reference.csv, lcurve.csv, ...)")
      ->required()
      ->check(CLI::ExistingDirectory);
  app.add_option("--axis", axis, "moving axis X|Y|Z (default: motion.csv '# axis', else X)")
      ->check(CLI::IsMember({"X", "Y", "Z", "x", "y", "z"}));
  app.add_option("--direction", direction,
                 "straightness direction X|Y|Z (default: '# straightness_direction', else Y)")
      ->check(CLI::IsMember({"X", "Y", "Z", "x", "y", "z"}));
  app.add_option("--local-length", o.local_length_mm,
                 "local straightness length in mm (default: a quarter of the travel)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--local-reference", local_ref, "reference line of the local straightness")
      ->check(CLI::IsMember({"end_points", "least_squares", "minimum_zone"}));
  app.add_option("--correlation", correlation,
                 "how per-point uncertainties combine: bound (any correlation) | uncorrelated")
      ->check(CLI::IsMember({"bound", "uncorrelated"}));
  app.add_option("--coverage-factor", o.evaluation.coverage_factor, "k of U = k u_c")
      ->check(CLI::PositiveNumber);
  app.add_option("--table-step", o.compensation.step_mm,
                 "point spacing of the uniform tables (Sinumerik, Beckhoff) in mm")
      ->check(CLI::PositiveNumber);
  app.add_option("--table-max-points", o.compensation.max_points,
                 "refuse uniform tables with more points (e.g. MD18342; 0 = no limit)");
  app.add_option("--remove-line", remove_line,
                 "line removed from S before tabulating: end_points | least_squares | "
                 "minimum_zone | none")
      ->check(CLI::IsMember({"end_points", "least_squares", "minimum_zone", "none"}));
  app.add_flag("--invert-error", invert,
               "S(x) > 0 means the carriage is displaced towards -direction (flips the tables)");
  app.add_option("--lincurve-points", o.lincurve_points, "LinuxCNC lincurve points (2..16)")
      ->check(CLI::Range(2, 16));
  app.add_option("--cec-input-axis", o.cec_input_axis,
                 "Sinumerik machine axis name of the moving axis (default AX1/AX2/AX3)");
  app.add_option("--cec-output-axis", o.cec_output_axis,
                 "Sinumerik machine axis name of the compensated axis");
  app.add_option("--cec-table", o.cec_table_index, "Sinumerik CEC table index t")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--beckhoff-axis", o.beckhoff_axis_number,
                 "Beckhoff logical number of the compensated axis (default 1/2/3 for X/Y/Z)");
  app.add_option("--beckhoff-master-axis", o.beckhoff_master_axis_number,
                 "Beckhoff logical number of the moving axis");
  app.add_option("--grid", grid, "displacement-method grid CSV (x_mm, y_mm, w_um[, m_um])")
      ->check(CLI::ExistingFile);
  app.add_option("--u-w", o.u_w_um,
                 "standard uncertainty of each w(x, y) node in um (from errsep-budget), when the "
                 "grid CSV has no u_w_um column")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--trend", o.trend_results_dir,
                 "the daemon's results store: add this machine's straightness over its past "
                 "scans (trend.csv) and flag a change beyond the combined U")
      ->check(CLI::ExistingDirectory);
  app.add_flag("--no-plots", no_plots, "do not run gnuplot (the report then has no figures)");
  app.add_flag("--no-tables", no_tables, "do not write compensation tables");
  app.add_option("--gnuplot", o.plot.gnuplot, "gnuplot program");
  CLI11_PARSE(app, argc, argv);

  using errsep::core::ReferenceLine;
  const std::map<std::string, ReferenceLine> lines = {
      {"end_points", ReferenceLine::end_points},
      {"least_squares", ReferenceLine::least_squares},
      {"minimum_zone", ReferenceLine::minimum_zone}};
  if (!axis.empty()) o.axis = axis[0];
  if (!direction.empty()) o.direction = direction[0];
  o.local_reference = lines.at(local_ref);
  o.evaluation.correlation = correlation == "uncorrelated" ? errsep::core::Correlation::uncorrelated
                                                           : errsep::core::Correlation::bound;
  if (remove_line == "none")
    o.compensation.remove_line.reset();
  else
    o.compensation.remove_line = lines.at(remove_line);
  o.compensation.error_sign = invert ? -1.0 : 1.0;
  o.plots = !no_plots;
  o.tables = !no_tables;
  o.grid_csv = grid;

  try {
    const auto r = errsep::io::write_scan_report(dir, o);
    if (const std::string swept = errsep::io::describe_swept(r.swept); !swept.empty())
      std::cout << swept << "\n";
    std::cout << r.text;
    for (const auto& w : r.warnings)
      std::cerr << "warning: " << w << "\n";
    if (r.lincurve_max_error_um >= 0)
      std::cout << "lincurve: max interpolation error " << r.lincurve_max_error_um << " um\n";
    std::cout << "wrote " << r.written.size() << " files, report: " << dir << "/report.html\n";
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "errsep-report: " << e.what() << "\n";
    return 1;
  }
}

// errsep-report: turns a result directory (errsep-separate / errsep-simulate / errsep-scan --out,
// errsep-refine --out or OUT/refine, a displacement-method result or grid CSV) into the ISO 230-1
// evaluation (evaluation.csv, evaluation.txt), figures (plots/), a self-contained report.html
// (with the refine steps when the set holds them; --pdf: report.pdf too) and CNC compensation
// tables in machine coordinates (compensation/, with each table's interpolation error in
// accuracy.csv).  errsep-scan makes the same report in OUT/report/ after every scan.
#include <CLI/CLI.hpp>
#include <exception>
#include <iostream>

#include "errsep/io/cnc/compensation_format.hpp"
#include "errsep/io/machine_config.hpp"
#include "errsep/io/scan_report.hpp"
#include "errsep/service/pdf_print.hpp"
#include "errsep/service/scan_report_job.hpp"
#include "errsep/version.hpp"

int main(int argc, char** argv) {
  using namespace errsep;
  CLI::App app{
      "errsep report: ISO 230-1 evaluation, plots, HTML report and CNC compensation tables "
      "for a result directory"};
  app.set_version_flag("--version", std::string(kVersion));
  std::string dir, config;
  io::ScanReportOptions o;
  std::string axis, direction, correlation = "bound", local_ref = "least_squares", remove_line;
  std::string grid;
  std::vector<std::string> formats, table_params;
  double table_step = 0;
  bool no_plots = false, no_tables = false, pdf = false;
  service::PdfOptions pdf_print;
  app.add_option("dir", dir, "result directory (motion.csv, reference.csv, lcurve.csv, ...)")
      ->required()
      ->check(CLI::ExistingDirectory);
  app.add_option("-c,--config", config,
                 "machine config: its [compensation] (formats, parameters) and, for a result that "
                 "does not record where the scan ran, its [axes] and [scan] slide_start_mm")
      ->check(CLI::ExistingFile);
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
  app.add_option("--formats", formats,
                 "compensation formats to write (default: [compensation] formats, else all): " +
                     io::compensation_format_names())
      ->delimiter(',');
  app.add_option("--table-param", table_params,
                 "a format's parameter, FORMAT.KEY=VALUE, e.g. sinumerik_cec.input_axis=X1 or "
                 "linuxcnc_hal.points=12 (repeatable; overrides the config)");
  app.add_option("--table-step", table_step,
                 "node spacing of every uniform table in mm (must divide the measured range; "
                 "default: chosen from the data and each controller's point limit)")
      ->check(CLI::PositiveNumber);
  app.add_option("--remove-line", remove_line,
                 "line removed from the error before tabulating: end_points (default) | "
                 "least_squares | minimum_zone | none")
      ->check(CLI::IsMember({"end_points", "least_squares", "minimum_zone", "none"}));
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
  app.add_flag("--pdf", pdf,
               "also print the report to report.pdf with headless Chromium (skipped, with the "
               "reason, when Chromium is absent)");
  app.add_option("--chromium", pdf_print.chromium, "Chromium program for --pdf")
      ->capture_default_str();
  app.add_option("--subdir", o.output_subdir,
                 "write the outputs into DIR/SUBDIR (errsep-scan writes OUT/report/) instead of "
                 "DIR itself");
  CLI11_PARSE(app, argc, argv);

  try {
    if (!config.empty()) {
      const io::ScanReportOptions from_config =
          service::report_options_from_config(io::load_machine_config(config));
      o.axes = from_config.axes;
      o.compensation = from_config.compensation;
      o.tables_export = from_config.tables_export;
      o.particulars = from_config.particulars;
    }
    o.pdf_printer = pdf ? service::chromium_pdf_printer(pdf_print) : nullptr;
    if (!axis.empty()) o.axis = axis[0];
    if (!direction.empty()) o.direction = direction[0];
    o.local_reference = *core::parse_reference_line(local_ref);
    o.evaluation.correlation =
        correlation == "uncorrelated" ? core::Correlation::uncorrelated : core::Correlation::bound;
    if (remove_line == "none")
      o.compensation.remove_line.reset();
    else if (!remove_line.empty())
      o.compensation.remove_line = *core::parse_reference_line(remove_line);
    if (!formats.empty()) {
      o.tables_export.formats.clear();
      for (const auto& f : formats) {
        const auto cf = io::parse_compensation_format(f);
        if (!cf)
          throw std::invalid_argument("--formats: '" + f + "' is not one of " +
                                      io::compensation_format_names());
        o.tables_export.formats.push_back(*cf);
      }
    }
    for (const auto f : io::all_compensation_formats()) {
      if (table_step <= 0 || f == io::CompensationFormat::linuxcnc_hal) continue;
      o.tables_export.parameters[f]["step_mm"] = std::to_string(table_step);
    }
    for (const auto& p : table_params) {
      const auto dot = p.find('.'), eq = p.find('=');
      const auto cf =
          dot == std::string::npos ? std::nullopt : io::parse_compensation_format(p.substr(0, dot));
      if (!cf || eq == std::string::npos || eq < dot)
        throw std::invalid_argument("--table-param '" + p +
                                    "': expected FORMAT.KEY=VALUE with FORMAT one of " +
                                    io::compensation_format_names());
      o.tables_export.parameters[*cf][p.substr(dot + 1, eq - dot - 1)] = p.substr(eq + 1);
    }
    o.plots = !no_plots;
    o.tables = !no_tables;
    o.grid_csv = grid;

    const auto r = io::write_scan_report(dir, o);
    service::print_report_outcome(r, dir, std::cout, std::cerr);
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "errsep-report: " << e.what() << "\n";
    return 1;
  }
}

#pragma once
// Turns a result directory into what a metrologist uses: the ISO 230-1 evaluation (CSV and
// text), figures (gnuplot), one self-contained HTML report, and compensation tables for the CNC.
//
// Inputs in DIR (formats fixed by the four-sensor and displacement apps):
//   motion.csv     x_mm, S_um, gamma_deg|gamma_urad [, u_S_um, u_gamma_urad]   (four-sensor)
//                  metadata: method, lambda, source (raw CSV), axis (default X),
//                  straightness_direction (default Y)
//   reference.csv  x_mm, f_um [, u_f_um]                                         (optional)
//   lcurve.csv     lambda, residual_norm, solution_norm, curvature; "# lambda_chosen", "#
//   lambda_rule"
//   residuals.csv  x_mm, config, residual_um (optional)
//   refine_steps.csv or refine/refine_steps.csv   the refine step table (io/refine_report.hpp),
//                  rendered with each step's residual and errors before -> after (optional)
//   raw.csv        the raw scan: its metadata gives the date and time and the sensors (optional)
//   a grid CSV     x_mm, y_mm, w_um
//   [, m_um | m_w_um] [, u_w_um]  (displacement method; found
//                  by its columns, or given as ScanReportOptions::grid_csv)
//   or, without motion.csv and grid, a one-axis displacement result
//                  x_mm, m_um, w_um [, r_um, u_m_um, u_w_um] (m: table motion error, EZX default)
// At least one of them must be present.
//
// Outputs in DIR (or DIR/<output_subdir>, e.g. OUT/report/ for errsep-scan): evaluation.csv (one
// row, ISO 230-1 symbols in the column names; an expanded uncertainty that is not known is an empty
// field, read back with CsvReadOptions::allow_empty), evaluation.txt, plots/*.png|svg|gp|dat,
// report.html, compensation/* (every CNC format of io/cnc/, in machine coordinates, and
// accuracy.csv).  DIR is a result set (io/staged_directory.hpp): it is refused when its manifest
// says it is not whole, raw scans in it are read with the plausibility checks, and the outputs join
// the set, which is committed anew whole (outputs of an earlier report are replaced, never mixed
// with these).
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "errsep/core/compensation.hpp"
#include "errsep/core/iso230.hpp"
#include "errsep/core/machine_axes.hpp"
#include "errsep/io/cnc/compensation_export.hpp"
#include "errsep/io/plots.hpp"

namespace errsep::io {

/// What a report for a customer states beyond the data (empty / nullopt: "not stated").
struct ReportParticulars {
  std::string machine;                  ///< e.g. "DMU 50 #3, Hall 2"
  std::string operator_name;            ///< who measured
  std::string instrument;               ///< e.g. "errsep four-sensor rig, Keyence GT2 probe"
  std::optional<double> temperature_c;  ///< environment temperature during the scan, °C
  /// Tolerance of the straightness of S (minimum zone, ISO 230-1): a verdict is given when set.
  std::optional<double> straightness_tolerance_um;
  bool is_valid(std::string* why) const;
};

/// What printing report.html to a PDF gave.
struct PdfOutcome {
  bool written = false;
  std::string why_not;  ///< when not written: what is missing or what failed, and what to do
};

/// Prints the local file `html` to `pdf`; never throws for a missing or failing printer (the
/// outcome says why).  The printer runs a program, which is not a file format: the service layer
/// gives one (service/pdf_print.hpp, headless Chromium).
using PdfPrinter =
    std::function<PdfOutcome(const std::filesystem::path& html, const std::filesystem::path& pdf)>;

struct ScanReportOptions {
  core::EvaluationOptions evaluation;
  /// Local straightness length; 0 = a quarter of the travel.
  double local_length_mm = 0;
  core::ReferenceLine local_reference = core::ReferenceLine::least_squares;
  /// Moving axis and straightness direction (X, Y or Z); 0 = from motion.csv metadata, else X / Y.
  char axis = 0;
  char direction = 0;
  core::CompensationOptions compensation;   ///< the line removed before tabulating
  CompensationExportOptions tables_export;  ///< CNC formats and their parameters
  /// Machine axes for a result that does not record them (motion.csv metadata slide_start_mm,
  /// scan_direction, reading_sign), e.g. from the machine config; nullopt = scan coordinates
  /// (with a warning).  The input/output letters follow `axis`/`direction` or the metadata.
  std::optional<core::MachineAxes> axes;
  bool tables = true;  ///< write compensation tables (four-sensor results only)
  bool plots = true;
  PlotOptions plot;
  std::filesystem::path grid_csv;  ///< empty = look for one in the directory
  /// Standard uncertainty of every w(x, y) node (from the displacement method's budget) when the
  /// grid CSV has no u_w_um column; 0 = not known.
  double u_w_um = 0;
  /// The daemon's results store: adds the straightness trend over its scans (trend.csv and a
  /// section of evaluation.txt; io/straightness_trend.hpp).  Empty = none.
  std::filesystem::path trend_results_dir;
  /// Sub-folder of DIR that receives every output ("report": errsep-scan's OUT/report/); empty =
  /// DIR itself (errsep-report's default).
  std::string output_subdir;
  ReportParticulars particulars;
  /// Also print report.html to report.pdf with this printer (service::chromium_pdf_printer),
  /// in the staging folder so that the PDF joins the set; when it could not, the HTML stands
  /// alone and ScanReportResult::pdf_skipped says why.  Empty: no PDF.
  PdfPrinter pdf_printer;
  bool is_valid(std::string* why) const;
};

struct ScanReportResult {
  std::vector<std::filesystem::path> written;
  /// Temporaries of interrupted errsep runs removed beside and in DIR (io::describe_swept).
  std::vector<std::filesystem::path> swept;
  std::string text;            ///< evaluation.txt
  std::filesystem::path html;  ///< report.html where it now is
  std::filesystem::path pdf;   ///< report.pdf where it now is; empty when none was made
  std::string pdf_skipped;     ///< why no PDF was made (empty when one was, or none was asked)
  std::string verdict;         ///< the conformance statement, empty without a tolerance
  std::vector<std::string> warnings;
  bool four_sensor = false, grid = false;
  /// One line per compensation table (points, range, interpolation error against U); empty
  /// when no table was made.
  std::string compensation_summary;
};

/// Evaluates DIR and writes the outputs into it.  Throws CsvError / std::runtime_error /
/// std::invalid_argument with a message naming the file and the problem.
ScanReportResult write_scan_report(const std::filesystem::path& dir,
                                   const ScanReportOptions& opts = {});

/// "12.34 ± 0.56" with U rounded to two significant digits and the value to the same decimal
/// place (GUM 7.2.6); without U ("—" for U <= 0) the value with 4 significant digits.
std::string format_value_with_uncertainty(double value, double expanded_uncertainty);

/// Conformance with an upper tolerance (ISO 14253-1 decision rule, the uncertainty counts against
/// the one who claims): "PASS" when value + U <= tolerance, "FAIL" when value - U > tolerance,
/// otherwise "NOT PROVEN" (the interval straddles the tolerance, or U is not known: U <= 0).
std::string conformance_verdict(double value, double expanded_uncertainty, double tolerance);

}  // namespace errsep::io

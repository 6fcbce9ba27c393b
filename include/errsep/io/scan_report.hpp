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
//   lambda_rule" residuals.csv  x_mm, config, residual_um (optional) refine.csv     free-form
//   numeric columns, rendered as a table                 (optional) a grid CSV     x_mm, y_mm, w_um
//   [, m_um | m_w_um] [, u_w_um]  (displacement method; found
//                  by its columns, or given as ScanReportOptions::grid_csv)
//   or, without motion.csv and grid, a one-axis displacement result
//                  x_mm, m_um, w_um [, r_um, u_m_um, u_w_um] (m: table motion error, EZX default)
// At least one of them must be present.
//
// Outputs in DIR: evaluation.csv (one row, ISO 230-1 symbols in the column names; an expanded
// uncertainty that is not known is an empty field, read back with CsvReadOptions::allow_empty),
// evaluation.txt, plots/*.png|svg|gp|dat, report.html, compensation/* (every CNC format of
// io/cnc/, in machine coordinates, and accuracy.csv).  DIR is a result set
// (io/staged_directory.hpp): it is refused when its manifest says it is not whole, raw scans in it
// are read with the plausibility checks, and the outputs join the set, which is committed anew
// whole (outputs of an earlier report are replaced, never mixed with these).
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "errsep/core/compensation.hpp"
#include "errsep/core/iso230.hpp"
#include "errsep/core/machine_axes.hpp"
#include "errsep/io/cnc/compensation_export.hpp"
#include "errsep/io/plots.hpp"

namespace errsep::io {

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
  bool is_valid(std::string* why) const;
};

struct ScanReportResult {
  std::vector<std::filesystem::path> written;
  /// Temporaries of interrupted errsep runs removed beside and in DIR (io::describe_swept).
  std::vector<std::filesystem::path> swept;
  std::string text;  ///< evaluation.txt
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

}  // namespace errsep::io

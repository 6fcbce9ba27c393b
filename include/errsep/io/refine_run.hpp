#pragma once
// The refine step as errsep-refine and errsep-scan --refine run it: raw four-sensor scan in,
// refinement loop (core/refine.hpp), optional truth and reference comparisons, files out.
//
//   DIR/refine_steps.csv        the step table (refine_report.hpp)
//   DIR/refine_report.txt       the readable report (+ the reference comparison)
//   DIR/refine_residual.csv     x_mm, config, t_s, residual_um of every reading under the final
//                               model, whiteness p-values in the metadata
//   DIR/motion.csv, reference.csv, lcurve.csv, residuals.csv, summary.txt
//                               the refined S, γ, f as a result directory
//                               (four_sensor_result_csv.hpp), "# model: zhao2019-eq1+gain" etc.
//   DIR/reference_comparison.csv  with a reference trace: x_mm, reference, before/after and their
//                               aligned differences (core/reference_comparison.hpp)
//
// Everything is read and checked before anything is written, the files are written into a
// staging directory next to DIR and moved into place at the end as one result set of kind
// "refine" (io/staged_directory.hpp): on an error or a kill DIR is left as it was (no
// half-written result, no files of two runs); DIR may hold nothing but an earlier refine result.
#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "errsep/core/reference_comparison.hpp"
#include "errsep/core/refine.hpp"
#include "errsep/core/sequence_refine.hpp"
#include "errsep/io/raw_scan_csv.hpp"

namespace errsep::io {

/// Geometry and readings of a complete raw four-sensor scan, ready for the core.
struct FourSensorInputs {
  core::FourSensorConfig cfg;
  Eigen::VectorXd x_mm;  ///< P slide positions from the file
  Eigen::MatrixXd m_um;  ///< P × 4
  Eigen::MatrixXd t_s;   ///< P × 4 reading times, or empty when the file has none
  /// A recorded scan sequence (raw_scan_csv.hpp) and its P × T readings; run_refine then also
  /// runs core::refine_four_sensor_sequence and writes sequence_refine.csv.
  std::optional<std::pair<core::ScanSequence, Eigen::MatrixXd>> sequence;
};

/// Geometry overrides (0 = from the file's metadata, Δx from x_mm when there is none).
struct GeometryOverrides {
  double dx_mm = 0;
  int s2 = 0, s3 = 0, s4 = 0;
};

/// Builds the inputs; `file` names the raw CSV in errors.  Throws CsvError ("file:line:
/// problem") when rows are off the Δx grid, the spacing does not fit, or values are not finite.
FourSensorInputs four_sensor_inputs(const RawFourSensorScan& raw, const std::filesystem::path& file,
                                    const GeometryOverrides& geometry = {});

struct RefineRunOptions {
  core::RefineOptions refine;
  std::optional<std::filesystem::path> truth_csv;      ///< read_truth_csv
  std::optional<std::filesystem::path> reference_csv;  ///< read_reference_csv
  std::string source;                                  ///< raw file named in the result metadata
  bool is_valid(std::string* why = nullptr) const { return refine.is_valid(why); }
};

/// The reference comparison of the separation before and after refinement, per profile the
/// reference has (S and f with the best-fit line removed, γ with its mean removed).
struct ReferenceReport {
  std::string file;
  std::optional<core::ReferenceComparison> S_before, S_after, gamma_before, gamma_after, f_before,
      f_after;
};

struct RefineRunResult {
  core::RefineResult result;
  /// With a recorded scan sequence: its refine, whose findings (result.report) are appended to
  /// `text` and written to sequence_refine.csv (refine_report.hpp).
  std::optional<core::SequenceRefineResult> sequence;
  std::optional<ReferenceReport> reference;
  std::string text;                          ///< the readable report written to the text file
  std::vector<std::filesystem::path> files;  ///< written, in DIR
  /// Temporaries of interrupted errsep runs removed from DIR's folder (io::describe_swept).
  std::vector<std::filesystem::path> swept;
};

/// Compares a separation with a reference trace (what the app reports).
ReferenceReport compare_with_reference(const core::FourSensorResult& before,
                                       const core::FourSensorResult& after,
                                       const Eigen::VectorXd& x_mm, double dx_mm,
                                       const std::filesystem::path& reference_csv);

/// The reference comparison as text (appended to the refine report).
std::string format_reference_text(const ReferenceReport& r);

/// Runs the loop on `in` and writes the files above into `out_dir`.  Truth and reference files
/// are read before anything is written.  Throws CsvError for bad inputs, std::invalid_argument
/// for bad options, std::runtime_error on I/O failure.
RefineRunResult run_refine(const FourSensorInputs& in, const std::filesystem::path& out_dir,
                           const RefineRunOptions& opts);

/// The same from a raw CSV file (read with require_complete).
RefineRunResult run_refine(const std::filesystem::path& raw_csv,
                           const std::filesystem::path& out_dir, const RefineRunOptions& opts,
                           const GeometryOverrides& geometry = {});

}  // namespace errsep::io

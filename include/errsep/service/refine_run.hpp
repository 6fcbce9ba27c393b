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
//                               (four_sensor_result_csv.hpp), "# model: zhao2019-eq1+gain" etc.;
//                               for a recorded sequence whose fit is the scan's result
//                               (service/sequence_result.hpp) the sequence's refined fit, as the
//                               scan's own files show it (the steps are then the single-scan
//                               refine of m1..m4, for comparison)
//   DIR/sequence_refine.csv     with a recorded sequence: its refine (io/refine_report.hpp)
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
#include "errsep/io/four_sensor_inputs.hpp"

namespace errsep::service {

struct RefineRunOptions {
  core::RefineOptions refine;
  std::optional<std::filesystem::path> truth_csv;      ///< read_truth_csv
  std::optional<std::filesystem::path> reference_csv;  ///< read_reference_csv
  std::string source;                                  ///< raw file named in the result metadata
  /// A recorded sequence's refine the caller has already made of the same readings with
  /// alpha = refine.alpha (the scan pipeline's): taken instead of being made again, so that one
  /// job refines a sequence once.  Null: run_refine makes it.  Must outlive the call.
  const core::SequenceRefineResult* sequence_refine = nullptr;
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
  /// The sequence's refine was the caller's (RefineRunOptions::sequence_refine), not made here.
  bool sequence_taken = false;
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
RefineRunResult run_refine(const io::FourSensorInputs& in, const std::filesystem::path& out_dir,
                           const RefineRunOptions& opts);

/// The same from a raw CSV file (read with require_complete).
RefineRunResult run_refine(const std::filesystem::path& raw_csv,
                           const std::filesystem::path& out_dir, const RefineRunOptions& opts,
                           const io::GeometryOverrides& geometry = {});

}  // namespace errsep::service

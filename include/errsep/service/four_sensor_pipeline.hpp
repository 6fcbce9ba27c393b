#pragma once
// The four-sensor pipeline, once for every program: a complete raw scan and the settings -> the
// separation (Zhao 2019) -> the optional refine step -> the result files.  errsep-scan,
// errsep-separate and errsep-daemon all go through it, so a scan's result folder is the same
// whoever made it:
//
//   raw.csv                 the raw scan (write_result_set only; errsep-scan writes its own)
//   motion.csv              S(x), γ(x) with their uncertainties      (io/four_sensor_result_csv)
//   reference.csv           f(x)
//   lcurve.csv              the λ search
//   residuals.csv           the residuals of the redundant equations
//   summary.txt             λ, σ̂, straightness, the rule that chose λ
//   refine/                 with refine on: the refine step's set of its own
//                           (service/refine_run.hpp); with a raw scan that records a scan
//                           sequence (io/raw_scan_csv.hpp) also refine/sequence_refine.csv
//                           (core/sequence_refine.hpp), and when the sequence fit is the result
//                           refine/motion.csv and the rest are that fit too, the one refine of
//                           the sequence made here taken by the refine step
//
// A raw scan that records a scan sequence (more than one traverse of a configuration, or a plan
// other than single: io/raw_scan_csv.hpp) is separated from all its traverses: motion.csv,
// reference.csv, residuals.csv and summary.txt are then the sequence fit's
// (core/sequence_refine.hpp, least squares, λ = 0) after its refine (effects the plan identifies
// applied, u_S widened for those it detects but cannot identify), with the ISO 230-1 straightness
// and its U from that fit's covariance and the plan named in summary.txt and motion.csv's
// metadata (`scan_plan`, `separation`); the single-scan separation of m1..m4 is kept in the
// pipeline's result for comparison only.  This is done with refine off too: it is the result.
//
// write_result_set() makes the whole folder one result set (io/staged_directory.hpp): written
// beside the target and moved into place in one rename, so a kill at any moment leaves the earlier
// set or the new one.  A separation that fails leaves a set holding the raw scan alone (no result
// is better than a partial one) and says why.  Not real-time safe.
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/refine.hpp"
#include "errsep/core/sequence_refine.hpp"
#include "errsep/io/machine_config.hpp"
#include "errsep/io/raw_scan_csv.hpp"

namespace errsep::service {

struct FourSensorPipelineOptions {
  /// The separation's options (errsep-separate sets every field; scan and daemon the gauge).
  core::FourSensorOptions separation =
      core::options_for_gauge(core::CurvatureGauge::reference_without_curvature);
  bool refine = false;         ///< run the refine step and write refine/
  double refine_alpha = 0.01;  ///< [refine] alpha: the refine step's significance level
  /// A reference trace for the refine step's comparison (implies nothing about `refine`).
  std::optional<std::filesystem::path> refine_reference;
  bool is_valid(std::string* why = nullptr) const;
};

/// The options a machine config gives ([separation]; [refine] enabled and alpha); a non-empty
/// `gauge` (core::curvature_gauge_from_string, the command line's) overrides [separation] gauge.
/// Throws std::invalid_argument naming an unknown gauge.
FourSensorPipelineOptions pipeline_options(const io::MachineConfig& cfg, const std::string& gauge);

/// What the pipeline did.
struct FourSensorPipelineResult {
  /// The result written (motion.csv): the sequence fit's with a recorded sequence (file
  /// comment), else the separation of m1..m4.  None when it failed (see error).
  std::optional<core::FourSensorResult> separation;
  /// With a recorded sequence: the single-scan separation of m1..m4 (not the result).
  std::optional<core::FourSensorResult> single_scan;
  std::optional<core::RefineResult> refine;  ///< with refine on
  /// With a recorded scan sequence: its fit and refine (the result's source); its findings are
  /// also in `warnings`.
  std::optional<core::SequenceRefineResult> sequence_refine;
  /// How many times the recorded sequence was refined in this job: 1 with a sequence (the
  /// refine step takes the pipeline's), 0 without.
  int sequence_refines = 0;
  std::vector<std::string> files;     ///< written, relative to the folder ("refine/" for the set)
  std::vector<std::string> warnings;  ///< for the user (λ fallbacks, an incomplete refined model)
  std::string error;                  ///< why the separation failed (write_result_set only)
};

class FourSensorPipeline {
 public:
  /// Throws std::invalid_argument naming the field when the options are invalid.
  explicit FourSensorPipeline(FourSensorPipelineOptions opts);

  /// Separates `raw` (complete, with its geometry) and writes the result files into `dir`, a
  /// staging folder the caller commits.  `raw_csv`: the raw scan as a file in `dir` (the refine
  /// step reads it); `source`: the raw file's name to record in the results' metadata (where it
  /// will be once the set is in place); `run_id`: the set's.  Throws on a failed separation or an
  /// I/O error (the caller keeps the raw data alone).
  FourSensorPipelineResult separate(const io::RawFourSensorScan& raw,
                                    const std::filesystem::path& dir,
                                    const std::filesystem::path& raw_csv, const std::string& source,
                                    const std::string& run_id) const;

  /// The whole result set at `out`: raw.csv, then separate(); staged and moved into place whole,
  /// replacing an earlier set of kind "scan" (`writer`, e.g. "errsep-daemon 0.3.0", goes into its
  /// manifest).  A failed separation gives a set with raw.csv alone and `error` set; I/O errors
  /// throw (the target then holds the earlier set, or nothing).
  FourSensorPipelineResult write_result_set(const io::RawFourSensorScan& raw,
                                            const std::filesystem::path& out,
                                            const std::string& writer) const;

  const FourSensorPipelineOptions& options() const noexcept { return opts_; }

 private:
  FourSensorPipelineOptions opts_;
};

}  // namespace errsep::service

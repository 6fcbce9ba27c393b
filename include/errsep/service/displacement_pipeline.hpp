#pragma once
// The displacement pipeline (Haramiishi 2024, one axis), once for every program: the recorded
// runs of a displacement scan and the settings -> the joint estimate of r, m, w with their
// uncertainties (core/displacement_joint.hpp) and the residuals of the redundant readings
// (core/displacement_residuals.hpp) -> the result files.  errsep-scan (--method displacement,
// both), errsep-separate-displacement one-axis and errsep-daemon ([scan] method) all go through
// it, so a displacement scan's result folder is the same whoever made it:
//
//   raw_displacement.csv        the raw scan (write_result_set only; errsep-scan writes its own)
//   displacement.csv            x_mm, r_um, m_um, w_um, u_r_um, u_m_um, u_w_um
//   (io/displacement_csv)
//                               with '# source:', the gauge, σ and where it came from: the one-axis
//                               result errsep-report reads
//   displacement_residuals.csv  the residuals of the redundant equations, σ̂ and whiteness
//   refine/displacement_refine.csv, refine/displacement.csv   with refine on: the loop's account
//                               (effect, decision, size ± u, predicted errors of w) and the
//                               refined profile with its u
//
// write_result_set() makes the whole folder one result set (io/staged_directory.hpp), as
// FourSensorPipeline does: a kill at any moment leaves the earlier set or the new one; a
// separation that fails leaves a set holding the raw scan alone and says why.  Not real-time safe.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "errsep/core/displacement_joint.hpp"
#include "errsep/core/displacement_method.hpp"
#include "errsep/core/displacement_refine_one_axis.hpp"
#include "errsep/core/displacement_residuals.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/displacement_csv.hpp"
#include "errsep/io/machine_config.hpp"
#include "errsep/io/raw_scan_csv.hpp"

namespace errsep::service {

/// The file names of a displacement result in a result folder.
inline constexpr const char* kDisplacementRawCsv = "raw_displacement.csv";
inline constexpr const char* kDisplacementResultCsv = "displacement.csv";
inline constexpr const char* kDisplacementResidualsCsv = "displacement_residuals.csv";
/// With refine on: the loop's account (io/displacement_refine_csv.hpp) and the refined profile.
inline constexpr const char* kDisplacementRefineCsv = "refine/displacement_refine.csv";
inline constexpr const char* kDisplacementRefinedCsv = "refine/displacement.csv";

struct DisplacementPipelineOptions {
  /// The traverse d of the reference piece; none: the scan's d_mm, else its sampling interval.
  std::optional<double> displacement_mm;
  double initial_um = 0.0;  ///< r(x_1) of Eq. (9)
  core::ChainJoin chain_join = core::ChainJoin::least_roughness;
  double displacement_sigma_mm = 0.0;      ///< u(d), added to the stated u (0 = d exact)
  std::optional<double> reading_sigma_um;  ///< σ of one reading; none: from the redundant ones
  core::DisplacementResidualOptions residuals;  ///< whiteness test of the residuals
  /// Close the loop (core/displacement_refine_one_axis.hpp) in separate() and write_result_set():
  /// errsep-scan --refine, [refine] enabled, the daemon with it.
  bool refine = false;
  core::OneAxisRefineOptions refine_options;
  bool is_valid(std::string* why = nullptr) const;
};

/// What the pipeline did.
struct DisplacementPipelineResult {
  std::optional<core::OneAxisJointResult> separation;  ///< none when it failed (see error)
  core::DisplacementResiduals residuals;
  io::CsvTable profile;            ///< displacement.csv's table
  io::CsvTable residual_table;     ///< displacement_residuals.csv's table
  std::vector<std::string> files;  ///< written, relative to the folder
  std::string error;               ///< why the separation failed (write_result_set only)
  std::optional<core::OneAxisRefineResult> refine;  ///< with options().refine
  /// The lines a program prints: the estimate, u(w) and σ (or why there is none), the gauge, the
  /// residual verdict.
  std::string brief_report() const;
};

class DisplacementPipeline {
 public:
  /// Throws std::invalid_argument naming the field when the options are invalid.
  explicit DisplacementPipeline(DisplacementPipelineOptions opts);

  /// Separates repeated runs of one measurement (the first names the grid and d; the others must
  /// share them: std::invalid_argument naming `names[k]` otherwise) with their mean; the tables
  /// are made, nothing is written.  `residuals_file`: where the residual table will be, named in
  /// the profile's metadata.
  DisplacementPipelineResult compute(const std::vector<io::OneAxisInput>& runs,
                                     const std::vector<std::string>& names,
                                     const std::string& residuals_file) const;

  /// Separates the raw scan recorded at `raw_csv` (a file in `dir`, as errsep-scan records it)
  /// and writes displacement.csv and displacement_residuals.csv into `dir`, a staging folder the
  /// caller commits.  `source`: the raw file's name to record (where it will be once the set is
  /// in place); `run_id`: the set's.  Throws on a failed separation or an I/O error.
  DisplacementPipelineResult separate(const std::filesystem::path& dir,
                                      const std::filesystem::path& raw_csv,
                                      const std::string& source, const std::string& run_id) const;

  /// The whole result set at `out`: raw_displacement.csv, then separate(); staged and moved into
  /// place whole, replacing an earlier set of kind "scan" (`writer` goes into its manifest).  A
  /// failed separation gives a set with the raw file alone and `error` set; I/O errors throw.
  DisplacementPipelineResult write_result_set(const io::RawDisplacementScan& raw,
                                              const std::filesystem::path& out,
                                              const std::string& writer) const;

  /// The loop (core/displacement_refine_one_axis.hpp) on one recorded run with its reading times
  /// (empty: equal steps in the paper's order); `input` names the run in messages.  Throws as
  /// compute().
  core::OneAxisRefineResult refine(const io::OneAxisInput& in, const Eigen::VectorXd& t1_s,
                                   const Eigen::VectorXd& t2_s, const std::string& input) const;

  const DisplacementPipelineOptions& options() const noexcept { return opts_; }

 private:
  DisplacementPipelineOptions opts_;
};

/// The options a machine config gives (its [refine]: enabled, alpha), as pipeline_options does
/// for the four-sensor pipeline: errsep-scan (--refine over it) and errsep-daemon.
DisplacementPipelineOptions displacement_pipeline_options(const io::MachineConfig& cfg);

/// The residual verdict in a result table's metadata ('residuals': the residual file,
/// 'residual_verdict': white or not, σ̂ and the whiteness p of each family).  Also used for the
/// two-axis result of errsep-separate-displacement.
void set_residual_metadata(io::CsvTable& t, const core::DisplacementResiduals& r,
                           const std::string& residuals_file);

}  // namespace errsep::service

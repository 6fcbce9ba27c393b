#pragma once
// The four-sensor result directory, written by errsep-separate, errsep-simulate and errsep-scan
// and read by errsep-report:
//   DIR/motion.csv     x_mm,S_um,gamma_deg,gamma_urad,u_S_um,u_gamma_urad        (P rows)
//   DIR/reference.csv  x_mm,f_um,u_f_um                                          (N rows)
//   DIR/lcurve.csv     lambda,residual_norm,solution_norm,curvature  (+ "# lambda_chosen")
//   DIR/residuals.csv  x_mm,config,residual_um                        (4P rows)
//                      a scan sequence's fit: x_mm,traverse,config,direction,t_s,residual_um,
//                      every reading of every traverse (P·T rows; ResultWriteInfo::traverses)
//   DIR/summary.txt    brief_report() (or ResultWriteInfo::title) and the identifiability
//                      assumptions
// Every file goes through write_file_atomic: a result is whole or absent.  γ is reported up to the
// constant e_4/(D2+D3+D4) (Eq. 19), u_* are standard uncertainties (k = 1) from the noise level
// implied by the redundant equations.
#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "errsep/core/four_sensor.hpp"

namespace errsep::io {

/// motion.csv metadata of a scan sequence result (service/sequence_result.cpp) that errsep-report
/// reads: γ's u about its best-fit constant and line (RMS, µrad), and "false" where the plan with
/// the effects applied does not determine γ's level (u_gamma_urad, in the e4 = 0 gauge, then
/// carries that level at every point).
inline constexpr const char* kMetaUGammaShapeUrad = "u_gamma_about_constant_and_line_urad_rms";
inline constexpr const char* kMetaGammaLevelDetermined = "gamma_level_determined_by_data";
/// motion.csv metadata of a scan sequence result: the angular deviation (max − min of γ, µrad)
/// and its U (k = 2) from the fit's covariance of γ, correlations included, so that γ's constant
/// cancels (core::sequence_angular_deviation); errsep-report takes them in place of propagating
/// u_gamma_urad pointwise.
inline constexpr const char* kMetaAngularDeviationUrad = "angular_deviation_urad";
inline constexpr const char* kMetaAngularDeviationUUrad = "angular_deviation_U_urad";

struct ResultWriteInfo {
  std::string source;  ///< raw-data file the result came from ("simulation" for errsep-simulate)
  std::string axis = "X";                    ///< moving axis (ISO 230-1 naming)
  std::string straightness_direction = "Y";  ///< direction of S
  std::vector<std::pair<std::string, std::string>> extra_metadata;
  /// motion.csv only: e.g. the straightness_* figures of a result whose covariance is not a
  /// core::FourSensorCovariance (a scan sequence's fit), written where the separation's own are.
  std::vector<std::pair<std::string, std::string>> motion_metadata = {};
  /// Lines appended to summary.txt (what the result is, when it is not the single separation).
  std::vector<std::string> summary_notes = {};
  /// The result's `estimator` and `uncertainty_model` metadata in place of the separation's own
  /// (a scan sequence's fit is not the posterior separation and carries no shrinkage); empty:
  /// the separation's.
  std::string estimator = {}, uncertainty_model = {};
  /// summary.txt's first line in place of FourSensorResult::brief_report() (a scan sequence's
  /// fit names itself); empty: brief_report().
  std::string title = {};
  /// A scan sequence's residual of every traverse: residuals.csv then holds all of them.
  struct TraverseResiduals {
    Eigen::MatrixXd residual_um;     ///< P × T, column k = traverse k
    Eigen::MatrixXd t_s;             ///< P × T reading times
    std::vector<int> configuration;  ///< T, 1..4
    std::vector<int> direction;      ///< T, +1 forward, −1 backward
  };
  std::optional<TraverseResiduals> traverses = {};
};

/// The machine axes a raw scan records (io/machine_axes_metadata.hpp) carried into a result:
/// the axis letters and slide_start_mm, scan_direction, reading_sign as extra metadata.  Leaves
/// `info` as it is when the raw scan does not record them.  Throws std::invalid_argument on a
/// malformed value.
void carry_machine_axes(const std::vector<std::pair<std::string, std::string>>& raw_metadata,
                        ResultWriteInfo& info);

/// Creates DIR if needed and writes the files above.  Throws std::runtime_error on I/O errors.
void write_four_sensor_result(const std::filesystem::path& dir, const core::FourSensorResult& r,
                              const ResultWriteInfo& info);

}  // namespace errsep::io

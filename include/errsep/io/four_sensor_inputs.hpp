#pragma once
// A raw four-sensor scan as the core takes it: the geometry (from the file's metadata, or given),
// the readings on the Δx grid (Zhao 2019 Eq. 5) and, for a recorded scan sequence, every
// traverse.  Checked where it is read: a row off the grid, a spacing that does not fit or a value
// that is not finite is a CsvError naming the file.
#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <utility>

#include "errsep/core/four_sensor_config.hpp"
#include "errsep/core/scan_sequence.hpp"
#include "errsep/io/raw_scan_csv.hpp"

namespace errsep::io {

/// Geometry and readings of a complete raw four-sensor scan, ready for the core.
struct FourSensorInputs {
  core::FourSensorConfig cfg;
  Eigen::VectorXd x_mm;  ///< P slide positions from the file
  Eigen::MatrixXd m_um;  ///< P × 4
  Eigen::MatrixXd t_s;   ///< P × 4 reading times, or empty when the file has none
  /// A recorded scan sequence (raw_scan_csv.hpp) and its P × T readings; the refine
  /// (service/refine_run.hpp) then also refines the sequence.
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

}  // namespace errsep::io

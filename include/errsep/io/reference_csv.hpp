#pragma once
// Independent traces for the refine step: a reference instrument's trace (laser interferometer,
// CMM) and, for simulations, the truth.
//
// Reference trace, on the instrument's own x grid (strictly increasing):
//   x_mm,S_um[,gamma_urad]        or   x_mm,f_um     (at least one of S_um, gamma_urad, f_um)
// Truth of a simulated scan, one row per reference point x_0 + j·Δx (j < N), the scan's slide
// positions being the first P rows:
//   x_mm,f_um,S_um,gamma_urad     (S_um and gamma_urad "nan" beyond row P)
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "errsep/core/four_sensor_config.hpp"
#include "errsep/core/refine.hpp"

namespace errsep::io {

struct ReferenceTrace {
  std::vector<double> x_mm;
  std::optional<std::vector<double>> S_um, gamma_urad, f_um;
};

/// Throws CsvError ("file:line: problem") for a missing x_mm column, no profile column, a
/// non-number or nan, or an x that does not increase.
ReferenceTrace read_reference_csv(const std::filesystem::path& file);

/// Reads the truth of a scan with geometry `cfg` whose first slide position is x0_mm.  Throws
/// CsvError for missing columns, rows off the Δx grid, too few rows, or nan where a value is
/// needed.
core::RefineTruth read_truth_csv(const std::filesystem::path& file,
                                 const core::FourSensorConfig& cfg, double x0_mm);

/// Writes `truth` in the form read_truth_csv reads (N rows from x0_mm on the Δx grid; S and γ
/// "nan" beyond the P slide positions), atomically.  Throws std::invalid_argument when the sizes
/// do not match cfg, std::runtime_error on I/O failure.
void write_truth_csv(const std::filesystem::path& file, const core::RefineTruth& truth,
                     const core::FourSensorConfig& cfg, double x0_mm,
                     const std::vector<std::pair<std::string, std::string>>& metadata = {});

}  // namespace errsep::io

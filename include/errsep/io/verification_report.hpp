#pragma once
// The record of measure - compensate - verify (core/compensation_verification.hpp), written by
// errsep-scan --verify-with into the second scan's result directory and shown by errsep-report:
//   verification.csv  x_mm (machine position), e_before_um, u_before_um, e_predicted_um,
//                     e_measured_um, u_measured_um; metadata: the three minimum-zone
//                     straightness values with their U, the difference, the verdict
//   verification.txt  the same in words
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "errsep/core/compensation_verification.hpp"
#include "errsep/io/csv.hpp"

namespace errsep::io {

struct VerificationInfo {
  std::string symbol;      ///< ISO 230-1 symbol, e.g. "EYX"
  std::string table_file;  ///< the compensation table applied
  std::string before;      ///< the first scan's result directory
  double coverage_factor = 2.0;
};

CsvTable verification_csv(const core::VerificationResult& r, const VerificationInfo& info);
std::string verification_text(const core::VerificationResult& r, const VerificationInfo& info);
/// Writes both files into dir, each atomically; returns their paths.
std::vector<std::filesystem::path> write_verification(const std::filesystem::path& dir,
                                                      const core::VerificationResult& r,
                                                      const VerificationInfo& info);

/// A four-sensor result's motion.csv (x_mm, S_um, u_S_um) as an error in machine coordinates,
/// through the axes it records; a result that records none is taken with `fallback` and
/// *warning says so.  Throws CsvError naming the file.
core::MachineError read_machine_error(const std::filesystem::path& result_dir,
                                      const core::MachineAxes& fallback, std::string* warning);

/// The first scan's result directory of a table errsep-report wrote into DIR/compensation/:
/// DIR, when it holds a motion.csv; else empty.
std::filesystem::path result_dir_of_table(const std::filesystem::path& table);

/// The rows (quantity, value with U) of a verification.csv, for a report table.  Throws CsvError
/// when a figure is missing.
std::vector<std::pair<std::string, std::string>> verification_rows(
    const CsvTable& csv, const std::filesystem::path& file);

}  // namespace errsep::io

#pragma once
// Writes a measured compensation for the chosen controllers: every format's table is made
// (within the measured range, within the controller's point limit), written, read back as the
// controller holds it, and its own interpolation error against the measurement (max, RMS) is
// measured on that read-back, compared with the measurement's expanded uncertainty U, written
// into the table file where the format has comments and into accuracy.csv beside the tables.
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "errsep/core/compensation.hpp"
#include "errsep/io/cnc/compensation_format.hpp"
#include "errsep/io/csv.hpp"

namespace errsep::io {

struct CompensationExportOptions {
  std::vector<CompensationFormat> formats = all_compensation_formats();
  std::map<CompensationFormat, CncParameters> parameters;  ///< per format; absent = defaults
  double coverage_factor = 2.0;                            ///< k of U = k u
  std::string title;                                       ///< provenance for the files
  /// Checks every format's parameters ("<format>.<key>: problem").
  bool is_valid(std::string* why) const;
};

struct ExportedTable {
  CompensationFormat format = CompensationFormat::csv;
  std::vector<CncFile> files;     ///< files[0] holds the table
  core::CompensationTable table;  ///< the nodes chosen
  ControllerTable read_back;      ///< files[0] read back as the controller holds it
  core::TableAccuracy accuracy;   ///< of read_back against the measurement
  std::string accuracy_line;      ///< the sentence written beside the table
};

struct CompensationExport {
  std::string symbol;           ///< ISO 230-1 symbol, e.g. "EYX"
  double measurement_U_um = 0;  ///< largest k u(c) over the measured range; 0 = unknown
  double coverage_factor = 2.0;
  std::vector<ExportedTable> tables;  ///< in the order of the options' formats
  /// One line per table: points, range, step, max and RMS error, against U.
  std::string summary() const;
  /// accuracy.csv: one row per table.
  CsvTable accuracy_csv() const;
};

/// Throws std::invalid_argument (bad options, a table the controller cannot hold) with the
/// format's name in the message.
CompensationExport export_compensation(const core::CompensationProfile& profile,
                                       const CompensationExportOptions& opts);

/// Writes every file and accuracy.csv into dir (created if needed), each atomically.  Returns the
/// paths written.
std::vector<std::filesystem::path> write_compensation_export(const std::filesystem::path& dir,
                                                             const CompensationExport& e);

}  // namespace errsep::io

#pragma once
// Plausibility of what an input file says it measured, checked where it is read and before any
// computation: every reading finite and within its sensor's measuring range, positions strictly
// increasing, times never going backwards.  A reading no sensor can give (a glitch, a corrupted
// file: -8.7e10 um) would otherwise reach the solvers and fail there without a file or a line,
// or worse, give a number.
//
// The range of a sensor is recorded by the scan in the raw file's metadata, from the machine
// config (io/machine_config.hpp, [[sensor]] range_min_um / range_max_um):
//   # range_min_m1_um: -2000         four-sensor scan: one pair per column m1..m4
//   # range_max_m1_um: 2000
//   # range_min_s1_um: -2000         displacement scan: s1 (workpiece), s2 (reference piece)
// A file without them (hand-made, simulated, written by an older errsep) is checked against
// +-kMaxPlausibleReadingUm instead, and the message says that the file records no range.
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "errsep/io/csv.hpp"

namespace errsep::io {

/// No displacement sensor used for these methods (capacitive, inductive, confocal, laser
/// triangulation probes) reads beyond +-100 mm: the bound for files that record no range.
inline constexpr double kMaxPlausibleReadingUm = 1e5;

struct ReadingRange {
  double min_um = -kMaxPlausibleReadingUm;
  double max_um = kMaxPlausibleReadingUm;
  bool recorded = false;  ///< from the file's metadata
};

/// Metadata keys of sensor `sensor`'s range ("m1" -> range_min_m1_um, range_max_m1_um).
std::string range_min_key(const std::string& sensor);
std::string range_max_key(const std::string& sensor);

/// The range of sensor `sensor` from the table's metadata, or the default bound when it records
/// none.  Throws CsvError for half a range, a non-number, or min >= max.
ReadingRange reading_range(const CsvTable& t, const std::string& sensor,
                           const std::filesystem::path& file);

/// The metadata lines of a range, as reading_range() reads them.
std::vector<std::pair<std::string, std::string>> range_metadata(const std::string& sensor,
                                                                double min_um, double max_um);

/// Every value of `column` finite and within `range` ("file:line: column 'm2_um': -8.7e+10 um is
/// outside the sensor's range -2000 to 2000 um ..."); NaN is passed over where `allow_nan` (cells
/// an incomplete scan did not reach).  The column must exist.
void check_readings(const CsvTable& t, const std::string& column, const ReadingRange& range,
                    const std::filesystem::path& file, bool allow_nan);

/// Every value of `column` finite (NaN passed over where `allow_nan`) and, from row to row,
/// strictly increasing (`strictly`: positions) or never decreasing (times).
void check_increasing(const CsvTable& t, const std::string& column, bool strictly,
                      const std::filesystem::path& file, bool allow_nan);

}  // namespace errsep::io

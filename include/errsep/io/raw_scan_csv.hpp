#pragma once
// The raw-scan CSV: what a scan recorded, before any separation.  Written by errsep-scan, read by
// errsep-separate, the refine app and the daemon.
//
// Four-sensor scan (Zhao 2019), one row per slide position x_n, one column per configuration:
//
//   # format: errsep raw four-sensor scan
//   # complete: true                       <- false: aborted/failed, cells not measured are nan
//   # dx_mm: 5                              <- geometry (FourSensorConfig), when known
//   # s2: 1 ...
//   x_mm,m1_um,m2_um,m3_um,m4_um[,t1_s,t2_s,t3_s,t4_s]
//
// t_i_s: mean time of the K averaged readings of configuration i, seconds since scan start.
//
// A scan measured as a sequence of traverses (core/scan_sequence.hpp: closing pass, reversed,
// interleaved; issue 16 item 2) records every traverse, in the order measured, as two more
// columns and one metadata line each:
//
//   # plan: reversed
//   # traverses: 8
//   # traverse_2: configuration 1, backward, start_s 34.0
//   x_mm,m1_um,...,m4_um[,t1_s..t4_s],k1_um,k1_t_s,k2_um,k2_t_s,...,k8_um,k8_t_s
//
// kK_um is traverse K's reading at x_n (whatever the direction, the row is the position) and
// kK_t_s its time.  m1..m4 (and t1..t4) hold the first traverse of each configuration, so a
// tool that knows no sequences still reads a valid four-sensor scan.  A file without "traverses"
// is the single plan (today's files).
// A scan also records each column's sensor range ("# range_min_m1_um: -2000", "# range_max_m1_um:
// 2000", ...; io/plausibility.hpp): the readers refuse, with "file:line:", a reading outside it
// (outside +-1e5 um when the file records none), inf anywhere, nan in a complete scan, positions
// that do not increase and times that go backwards -- before anything is computed.  A raw scan
// in a result folder (io/staged_directory.hpp) is read only when its folder is a whole set.
//
// Displacement-method scan (Haramiishi 2024, Eqs. 1-3): S1 reads the workpiece, S2 the
// reference piece; scan 2 after the reference piece was displaced by d:
//
//   # format: errsep raw displacement scan
//   # d_mm: 5
//   # scan2_order: backward                 <- absent: forward (core/displacement_scan_order.hpp)
//   x_mm,s1_scan1_um,s2_scan1_um,s1_scan2_um,s2_scan2_um[,t_scan1_s,t_scan2_s]
//
// A row is a position whatever the order; scan 1 reads the rows top down, scan 2 top down
// (forward) or bottom up (backward), and its times t_scan2_s must go that way.
#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "errsep/core/displacement_scan_order.hpp"
#include "errsep/core/four_sensor_config.hpp"
#include "errsep/core/scan_sequence.hpp"
#include "errsep/io/csv.hpp"

namespace errsep::io {

inline constexpr const char* kRawFourSensorFormat = "errsep raw four-sensor scan";
inline constexpr const char* kRawDisplacementFormat = "errsep raw displacement scan";

/// The traverses of a scan sequence as recorded (file comment).
struct RawSequence {
  std::string plan = "custom";            ///< core::ScanSequence::name
  std::vector<core::Traverse> traverses;  ///< T, in the order measured
  std::vector<std::vector<double>> m_um;  ///< T columns of P: traverse k's reading at x_n
  std::vector<std::vector<double>> t_s;   ///< T columns of P: its reading times, s
};

struct RawFourSensorScan {
  std::vector<double> x_mm;                 ///< P slide positions
  std::array<std::vector<double>, 4> m_um;  ///< m_i(x_n), P each; nan where not measured
  std::optional<std::array<std::vector<double>, 4>> t_s;  ///< reading times, s since start
  std::optional<core::FourSensorConfig> geometry;         ///< from metadata dx_mm, s2, s3, s4, N
  std::optional<RawSequence> sequence;  ///< a scan sequence's traverses; none = single plan
  bool complete = false;                ///< "# complete: true" (absent = false)
  /// Other "# key: value" lines (counts, timestamps, config, ...), in order, written after the
  /// format/complete/geometry lines.
  std::vector<std::pair<std::string, std::string>> metadata;
  /// 1-based line of each row in the file it was read from (empty when built in memory), for
  /// error messages that name the line.
  std::vector<std::size_t> row_line;

  std::size_t positions() const { return x_mm.size(); }
  /// The source line of row n, or 0 when unknown.
  std::size_t line_of(std::size_t n) const { return n < row_line.size() ? row_line[n] : 0; }
  /// Value of a metadata key, or nullopt.
  std::optional<std::string> meta(const std::string& key) const;
};

struct RawDisplacementScan {
  std::vector<double> x_mm;
  std::vector<double> s1_scan1_um, s2_scan1_um, s1_scan2_um, s2_scan2_um;
  std::optional<std::vector<double>> t_scan1_s, t_scan2_s;
  double d_mm = 0.0;
  /// The order scan 2 read the rows in (scan 1 reads them top down).
  core::DisplacementScanOrder scan2_order = core::DisplacementScanOrder::forward;
  bool complete = false;
  std::vector<std::pair<std::string, std::string>> metadata;
  std::optional<std::string> meta(const std::string& key) const;
};

/// Builds the CSV table (for writing, or for tests).  Throws std::invalid_argument when the
/// columns' lengths differ.
CsvTable to_csv_table(const RawFourSensorScan& scan);
CsvTable to_csv_table(const RawDisplacementScan& scan);

/// The sequence as core's fit takes it: the traverses (speed from the first traverse's recorded
/// times, or 10 mm/s when it has one reading) and the P × T readings; for a file without a
/// sequence, the single plan from m1..m4.  Throws std::invalid_argument without a geometry.
std::pair<core::ScanSequence, Eigen::MatrixXd> scan_sequence_of(const RawFourSensorScan& scan);

/// Records readings m (P × T, column k = traverse k of `seq`) and their times t (P × T) as
/// scan.sequence, and m1..m4, t1..t4 as the first traverse of each configuration (file comment).
/// Throws std::invalid_argument for shapes that do not match.
void set_sequence(RawFourSensorScan& scan, const core::ScanSequence& seq,
                  const Eigen::MatrixXd& m_um, const Eigen::MatrixXd& t_s);

/// Writes atomically (write_csv).  Throws std::runtime_error / std::invalid_argument.
void write_raw_four_sensor_csv(const std::filesystem::path& file, const RawFourSensorScan& scan);
void write_raw_displacement_csv(const std::filesystem::path& file, const RawDisplacementScan& scan);

struct RawReadOptions {
  /// Refuse a file marked "# complete: false" (or without the key) with a CsvError that says so.
  /// Tools that separate must not present a partial scan as a result; set false to inspect one.
  bool require_complete = true;
};

/// Reads a four-sensor raw scan: columns x_mm, m1_um..m4_um required, t1_s..t4_s optional (all
/// four or none).  Completeness: a file written by a scan (it has a "# format:" line) is complete
/// only with "# complete: true"; any other CSV with those columns (hand-made, simulated) is taken
/// as complete unless it says "# complete: false".  Throws CsvError ("file:line: problem") for
/// missing columns, non-numbers, nan in a complete scan, a bad geometry line, or an incomplete
/// scan when require_complete is set.
RawFourSensorScan read_raw_four_sensor_csv(const std::filesystem::path& file,
                                           const RawReadOptions& opts = {});
RawDisplacementScan read_raw_displacement_csv(const std::filesystem::path& file,
                                              const RawReadOptions& opts = {});

}  // namespace errsep::io

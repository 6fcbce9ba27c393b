#pragma once
// The CNC compensation formats errsep writes, behind one small interface and one registry.
//
// Every format turns a CompensationProfile (c = -e at machine positions, core/compensation.hpp)
// into the file(s) its controller loads, and reads its own main file back as the controller
// applies it, so that the interpolation error a table really has (nodes, rounding, truncation) is
// measured on the file itself, not on an idealised table.  A format knows its own parameters
// (machine axis names, table numbers, point limits): callers pass them as a name -> value map, so
// the config parser and the apps know no format's fields (ros2_control's HardwareInfo idea).
//
// The formats (each documented, with its sources, in its own header):
//   sinumerik_cec       Siemens Sinumerik 840D/828D sag/angularity compensation (CEC)   .ini
//   linuxcnc_hal        LinuxCNC 2.9 HAL: lincurve + external offsets, absolute          .hal
//   beckhoff_crosscomp  Beckhoff TwinCAT CNC cross compensation list (kw.crosscomp)     .lis
//   heidenhain_com      HEIDENHAIN TNC nonlinear axis error compensation .COM + .CMA    .COM
//   csv                 errsep's own table: x_mm (machine), comp_um                      .csv
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "errsep/core/compensation.hpp"

namespace errsep::io {

enum class CompensationFormat {
  sinumerik_cec,
  linuxcnc_hal,
  beckhoff_crosscomp,
  heidenhain_com,
  csv
};

/// The format's name as written in configs and on the command line ("sinumerik_cec", ...).
const char* to_string(CompensationFormat f) noexcept;
/// The inverse of to_string, or nullopt.
std::optional<CompensationFormat> parse_compensation_format(std::string_view name);
/// Every format, in a fixed order.
const std::vector<CompensationFormat>& all_compensation_formats();
/// "sinumerik_cec, linuxcnc_hal, ..." (for messages).
std::string compensation_format_names();

/// Parameters of one format: name -> value, as written in [compensation.<format>].
using CncParameters = std::map<std::string, std::string>;

struct CncFile {
  std::string name;  ///< file name, no directory
  std::string content;
};

/// What a writer needs besides the table.
struct CncWriteInfo {
  std::string title;  ///< provenance (written as a comment where the format has comments)
  /// One line on the table's own interpolation error, written beside the values where the format
  /// allows comments (empty on the first pass, when it is not known yet).
  std::string accuracy_line;
};

/// A table read back from a file, as its controller applies it.
struct ControllerTable {
  char input_axis = 0;   ///< the moving axis, when the file says (else 0)
  char output_axis = 0;  ///< the compensated axis, when the file says (else 0)
  /// Nodes at machine positions (mm) and the values the controller holds (um), linear between,
  /// end values held outside.
  core::CompensationTable table;
  /// Bound of what is not piecewise linear in the controller (e.g. LinuxCNC's whole counts), um.
  double extra_um = 0;
  /// Compensation the controller applies at machine position p (um).
  double apply_um(double p_mm) const { return table.at(p_mm); }
};

class CompensationWriter {
 public:
  virtual ~CompensationWriter() = default;
  virtual CompensationFormat format() const = 0;
  /// One line for file lists and reports.
  virtual std::string description() const = 0;
  /// Suffix of the main file (".ini", ".COM", ...).
  virtual const char* suffix() const = 0;
  /// Parameters understood, name -> meaning (with the default).
  virtual std::vector<std::pair<std::string, std::string>> parameters() const = 0;
  /// Throws std::invalid_argument("<parameter>: <problem>") on an unknown or bad parameter.
  virtual void validate(const CncParameters& params) const = 0;
  /// The nodes this controller gets (uniform within its point limit, or free breakpoints).
  virtual core::CompensationTable make_table(const core::CompensationProfile& profile,
                                             const CncParameters& params) const = 0;
  /// The file(s); files[0] holds the table.  The axes name the files (ISO 230-1 symbol, e.g.
  /// EYX) and the controller's axes where the parameters do not.
  virtual std::vector<CncFile> write(const core::CompensationTable& table,
                                     const core::MachineAxes& axes, const CncParameters& params,
                                     const CncWriteInfo& info) const = 0;
  /// Reads a main file back.  Throws std::runtime_error "name:line: problem".
  virtual ControllerTable read(const std::string& text, const std::string& name) const = 0;
};

/// The writer of a format (one static instance each).
const CompensationWriter& compensation_writer(CompensationFormat f);

/// The format a file name stands for, from its suffix (case-insensitive), or nullopt.
std::optional<CompensationFormat> compensation_format_of(const std::filesystem::path& file);

/// Reads a table file of any errsep format (chosen by compensation_format_of).  Throws
/// std::runtime_error naming the file and the problem.
ControllerTable read_compensation_file(const std::filesystem::path& file);

}  // namespace errsep::io

#pragma once
// Shared by the CNC table writers: reading a format's parameters (name -> text) with their
// defaults and limits, and the small text helpers every format needs.
#include <string>
#include <utility>
#include <vector>

#include "errsep/core/compensation.hpp"
#include "errsep/io/cnc/compensation_format.hpp"

namespace errsep::io::cnc {

/// Reads typed parameters; every error is std::invalid_argument("<format>.<key>: <problem>").
class ParameterReader {
 public:
  /// Refuses parameters not in `known` (a misspelt key must not fall back to a default).
  ParameterReader(const CncParameters& params,
                  const std::vector<std::pair<std::string, std::string>>& known,
                  std::string format);
  std::string text(const std::string& key, const std::string& dflt) const;
  long integer(const std::string& key, long dflt, long lo, long hi) const;
  double number(const std::string& key, double dflt, double lo, double hi) const;
  [[noreturn]] void fail(const std::string& key, const std::string& problem) const;

 private:
  const CncParameters& params_;
  std::string format_;
};

/// The parameters of a uniform table ("max_points", "step_mm"), for parameters() lists.
std::vector<std::pair<std::string, std::string>> uniform_table_parameters(
    std::size_t default_max_points, const std::string& limit_note);
/// Reads them.
core::UniformTableOptions uniform_table_options(const ParameterReader& r,
                                                std::size_t default_max_points);

/// "%.<decimals>f" without a "-0.000" for zero.
std::string fixed(double v, int decimals);
/// A comment text that cannot break out of its line.
std::string one_line(std::string s);
/// Letters, digits, '_', '-', '.' only (axis and HAL names).
bool plain_name(const std::string& s);
/// 1, 2, 3 for X, Y, Z (the usual logical axis numbers).
int axis_number(char axis);
/// Lower-case letter of an axis.
char lower(char axis);

/// Line-by-line reading of a table file for the readers: "name:line: problem" errors.
[[noreturn]] void read_fail(const std::string& name, std::size_t line, const std::string& problem);
/// Parses a whole decimal number (optional sign) or fails naming the line.
double read_number(const std::string& s, const std::string& name, std::size_t line);

}  // namespace errsep::io::cnc

#include "errsep/io/plausibility.hpp"
#include "errsep/io/csv.hpp"

#include <cmath>
#include <cstdio>

namespace errsep::io {
namespace {

std::size_t line_of(const CsvTable& t, std::size_t row) {
  return row < t.row_line.size() ? t.row_line[row] : 0;
}

std::size_t column_index(const CsvTable& t, const std::string& column,
                         const std::filesystem::path& file) {
  const auto c = t.find_column(column);
  if (!c) (void)t.column(column, file);  // throws "missing column" with the header's names
  return *c;
}

}  // namespace

std::string range_min_key(const std::string& sensor) {
  return "range_min_" + sensor + "_um";
}
std::string range_max_key(const std::string& sensor) {
  return "range_max_" + sensor + "_um";
}

ReadingRange reading_range(const CsvTable& t, const std::string& sensor,
                           const std::filesystem::path& file) {
  const std::string lo = range_min_key(sensor), hi = range_max_key(sensor);
  const bool has_lo = t.meta(lo).has_value(), has_hi = t.meta(hi).has_value();
  if (!has_lo && !has_hi) return {};
  if (has_lo != has_hi)
    throw CsvError(file, t.meta_line(has_lo ? lo : hi),
                   "metadata has '" + (has_lo ? lo : hi) + "' but not '" + (has_lo ? hi : lo) +
                       "': give both ends of the sensor's range or neither");
  ReadingRange r{*t.meta_number(lo, file), *t.meta_number(hi, file), true};
  if (!(r.min_um < r.max_um))
    throw CsvError(file, t.meta_line(lo),
                   "metadata range of sensor " + sensor + ": " + lo + " = " +
                       format_number(r.min_um) + " is not below " + hi + " = " +
                       format_number(r.max_um));
  return r;
}

std::vector<std::pair<std::string, std::string>> range_metadata(const std::string& sensor,
                                                                double min_um, double max_um) {
  return {{range_min_key(sensor), format_number(min_um)},
          {range_max_key(sensor), format_number(max_um)}};
}

void check_readings(const CsvTable& t, const std::string& column, const ReadingRange& range,
                    const std::filesystem::path& file, bool allow_nan) {
  const std::size_t c = column_index(t, column, file);
  for (std::size_t r = 0; r < t.rows.size(); ++r) {
    const double v = t.rows[r][c];
    if (std::isnan(v) && allow_nan) continue;
    if (!std::isfinite(v))
      throw CsvError(file, line_of(t, r),
                     "column '" + column + "': " + format_number(v) + " is not a finite reading" +
                         (std::isnan(v) ? " (nan: not measured, in a scan marked complete)" : ""));
    if (v < range.min_um || v > range.max_um)
      throw CsvError(
          file, line_of(t, r),
          "column '" + column + "': " + format_number(v) + " um is outside " +
              (range.recorded ? "the sensor's range " + format_number(range.min_um) + " to " +
                                    format_number(range.max_um) + " um recorded in the file"
                              : "+-" + format_number(kMaxPlausibleReadingUm) +
                                    " um, beyond any displacement sensor (the file "
                                    "records no range for this sensor)") +
              ": a reading no sensor can give");
  }
}

void check_increasing(const CsvTable& t, const std::string& column, bool strictly,
                      const std::filesystem::path& file, bool allow_nan) {
  const std::size_t c = column_index(t, column, file);
  bool have_prev = false;
  double prev = 0;
  std::size_t prev_line = 0;
  for (std::size_t r = 0; r < t.rows.size(); ++r) {
    const double v = t.rows[r][c];
    if (std::isnan(v) && allow_nan) continue;
    if (!std::isfinite(v))
      throw CsvError(file, line_of(t, r),
                     "column '" + column + "': " + format_number(v) + " is not finite");
    if (have_prev && (strictly ? !(v > prev) : v < prev))
      throw CsvError(
          file, line_of(t, r),
          "column '" + column + "': " + format_number(v) + " after " + format_number(prev) +
              (prev_line ? " (line " + std::to_string(prev_line) + ")" : "") +
              (strictly ? ": positions must increase from row to row" : ": time goes backwards"));
    have_prev = true;
    prev = v;
    prev_line = line_of(t, r);
  }
}

}  // namespace errsep::io

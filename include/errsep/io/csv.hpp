#pragma once
// errsep's CSV convention, shared by every app:
//
//   # errsep <kind> v<version>          <- optional comment/metadata lines, "# key: value"
//   # units: x in mm, profiles in um
//   x_mm,m1_um,m2_um,m3_um,m4_um         <- one header line; the unit is the name's suffix
//   0,0.12,...                           <- numeric rows, all the same width
//
// Reading reports the first problem as "file:line: what is wrong" and never returns a partial
// table.  Writing goes through write_file_atomic, so a result file is whole or absent.
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace errsep::io {

/// Error in a CSV file: what() is "file:line: problem" (line 0 when it concerns the whole file).
class CsvError : public std::runtime_error {
 public:
  CsvError(const std::filesystem::path& file, std::size_t line, const std::string& problem);
  std::size_t line() const noexcept { return line_; }

 private:
  std::size_t line_;
};

struct CsvTable {
  std::vector<std::pair<std::string, std::string>> metadata;  ///< "# key: value" lines, in order
  std::vector<std::string> columns;                           ///< header names, units as suffix
  std::vector<std::vector<double>> rows;                      ///< rows.size() x columns.size()
  std::vector<std::size_t> row_line;  ///< 1-based source line of each row (empty when built)
  std::size_t header_line = 0;        ///< 1-based source line of the header (0 when built)
  /// 1-based source line of each metadata entry (empty, or shorter, when built by set_meta).
  std::vector<std::size_t> metadata_line;

  /// Index of a column, or nullopt.
  std::optional<std::size_t> find_column(const std::string& name) const;
  /// All values of a named column; throws CsvError(file, 0, "missing column 'x'") when absent.
  std::vector<double> column(const std::string& name, const std::filesystem::path& file = {}) const;
  /// Value of a metadata key, or nullopt.
  std::optional<std::string> meta(const std::string& key) const;
  /// The 1-based source line of a metadata key, or 0 when it is absent or the table was built
  /// (so that an error about a metadata value can say file:line).
  std::size_t meta_line(const std::string& key) const;
  /// Value of a metadata key as a finite number, or nullopt when the key is absent; throws
  /// CsvError(file, meta_line(key), "metadata 'key: value': not a number") when it is not one.
  std::optional<double> meta_number(const std::string& key,
                                    const std::filesystem::path& file = {}) const;
  void set_meta(const std::string& key, const std::string& value);
  void add_column(const std::string& name, const std::vector<double>& values);
};

struct CsvReadOptions {
  bool allow_non_finite = false;  ///< NaN/Inf in a cell is an error unless this is set
  std::size_t min_rows = 1;       ///< fewer data rows is an error
  bool allow_empty = false;       ///< an empty cell (unknown) reads as NaN instead of an error
};

/// Reads a CSV file; throws CsvError naming file and line on any malformed content.
CsvTable read_csv(const std::filesystem::path& file, const CsvReadOptions& opts = {});
/// The same from text already in memory; `name` stands for the file in messages.
CsvTable parse_csv(const std::string& text, const std::filesystem::path& name,
                   const CsvReadOptions& opts = {});

/// How format_csv writes a cell that is not a finite number.
enum class NonFiniteCell {
  text,  ///< "nan", "inf" (a value that is not a number)
  empty  ///< an empty field: the value is unknown (read back with allow_empty)
};

/// Formats a table as CSV text (metadata as "# key: value" lines, then header, then rows).
std::string format_csv(const CsvTable& table, int significant_digits = 10,
                       NonFiniteCell non_finite = NonFiniteCell::text);

/// A number as errsep writes it in metadata, labels and config text: "%.10g" (the CSV cells'
/// default precision), so a value read back from any of them is the same to 10 digits.
std::string format_number(double v);

/// Writes atomically (see write_file_atomic).  Throws std::runtime_error on I/O failure.
void write_csv(const std::filesystem::path& file, const CsvTable& table,
               int significant_digits = 10);

}  // namespace errsep::io

#include "errsep/io/csv.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <limits>
#include <sstream>

#include "errsep/io/atomic_file.hpp"

namespace errsep::io {
namespace {

std::string where(const std::filesystem::path& file, std::size_t line) {
  std::string s = file.empty() ? std::string("<table>") : file.string();
  if (line > 0) s += ":" + std::to_string(line);
  return s;
}

std::string trim(std::string_view s) {
  std::size_t b = 0, e = s.size();
  while (b < e && (s[b] == ' ' || s[b] == '\t' || s[b] == '\r'))
    ++b;
  while (e > b && (s[e - 1] == ' ' || s[e - 1] == '\t' || s[e - 1] == '\r'))
    --e;
  return std::string(s.substr(b, e - b));
}

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::size_t start = 0;
  for (;;) {
    const std::size_t comma = line.find(',', start);
    out.push_back(trim(std::string_view(line).substr(start, comma - start)));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

}  // namespace

CsvError::CsvError(const std::filesystem::path& file, std::size_t line, const std::string& problem)
    : std::runtime_error(where(file, line) + ": " + problem), line_(line) {}

std::optional<std::size_t> CsvTable::find_column(const std::string& name) const {
  for (std::size_t i = 0; i < columns.size(); ++i)
    if (columns[i] == name) return i;
  return std::nullopt;
}

std::vector<double> CsvTable::column(const std::string& name,
                                     const std::filesystem::path& file) const {
  const auto idx = find_column(name);
  if (!idx) {
    std::string have;
    for (const auto& c : columns)
      have += (have.empty() ? "" : ", ") + c;
    throw CsvError(file, columns.empty() ? 0 : (header_line > 0 ? header_line : 1),
                   "missing column '" + name + "' (header has: " + have + ")");
  }
  std::vector<double> v;
  v.reserve(rows.size());
  for (const auto& r : rows)
    v.push_back(r[*idx]);
  return v;
}

std::optional<std::string> CsvTable::meta(const std::string& key) const {
  for (const auto& [k, v] : metadata)
    if (k == key) return v;
  return std::nullopt;
}

std::size_t CsvTable::meta_line(const std::string& key) const {
  for (std::size_t i = 0; i < metadata.size(); ++i)
    if (metadata[i].first == key) return i < metadata_line.size() ? metadata_line[i] : 0;
  return 0;
}

std::optional<double> CsvTable::meta_number(const std::string& key,
                                            const std::filesystem::path& file) const {
  const auto v = meta(key);
  if (!v) return std::nullopt;
  double out = 0;
  const auto [p, ec] = std::from_chars(v->data(), v->data() + v->size(), out);
  if (ec != std::errc() || p != v->data() + v->size() || !std::isfinite(out))
    throw CsvError(file, meta_line(key), "metadata '" + key + ": " + *v + "': not a number");
  return out;
}

void CsvTable::set_meta(const std::string& key, const std::string& value) {
  for (auto& [k, v] : metadata)
    if (k == key) {
      v = value;
      return;
    }
  metadata.emplace_back(key, value);
}

void CsvTable::add_column(const std::string& name, const std::vector<double>& values) {
  if (!rows.empty() && values.size() != rows.size())
    throw std::invalid_argument("add_column '" + name + "': " + std::to_string(values.size()) +
                                " values for " + std::to_string(rows.size()) + " rows");
  if (rows.empty()) rows.resize(values.size());
  columns.push_back(name);
  for (std::size_t i = 0; i < values.size(); ++i)
    rows[i].push_back(values[i]);
}

namespace {

CsvTable read_stream(std::istream& in, const std::filesystem::path& file,
                     const CsvReadOptions& opts) {
  CsvTable t;
  std::string line;
  std::size_t lineno = 0;
  bool have_header = false;
  while (std::getline(in, line)) {
    ++lineno;
    const std::string s = trim(line);
    if (s.empty()) continue;
    if (s[0] == '#') {
      const std::string body = trim(std::string_view(s).substr(1));
      const auto colon = body.find(':');
      if (colon != std::string::npos)
        t.metadata.emplace_back(trim(std::string_view(body).substr(0, colon)),
                                trim(std::string_view(body).substr(colon + 1)));
      else if (!body.empty())
        t.metadata.emplace_back(body, "");
      t.metadata_line.resize(t.metadata.size(), lineno);
      continue;
    }
    auto cells = split(s);
    if (!have_header) {
      for (std::size_t i = 0; i < cells.size(); ++i) {
        if (cells[i].empty())
          throw CsvError(file, lineno,
                         "empty column name in header (column " + std::to_string(i + 1) + ")");
        for (std::size_t j = 0; j < i; ++j)
          if (cells[j] == cells[i])
            throw CsvError(file, lineno, "duplicate column '" + cells[i] + "' in header");
      }
      t.columns = std::move(cells);
      t.header_line = lineno;
      have_header = true;
      continue;
    }
    if (cells.size() != t.columns.size())
      throw CsvError(file, lineno,
                     "expected " + std::to_string(t.columns.size()) + " values (" +
                         std::to_string(t.columns.size()) + " columns in header), found " +
                         std::to_string(cells.size()));
    std::vector<double> row(cells.size());
    for (std::size_t i = 0; i < cells.size(); ++i) {
      const std::string& c = cells[i];
      double v = 0;
      const char* b = c.data();
      const char* e = c.data() + c.size();
      if (c.empty() && opts.allow_empty) {
        row[i] = std::numeric_limits<double>::quiet_NaN();
        continue;
      }
      if (!c.empty() && *b == '+') ++b;
      const auto [ptr, ec] = std::from_chars(b, e, v);
      if (c.empty() || ec != std::errc() || ptr != e)
        throw CsvError(file, lineno, "column '" + t.columns[i] + "': '" + c + "' is not a number");
      if (!std::isfinite(v) && !opts.allow_non_finite)
        throw CsvError(file, lineno, "column '" + t.columns[i] + "': non-finite value '" + c + "'");
      row[i] = v;
    }
    t.rows.push_back(std::move(row));
    t.row_line.push_back(lineno);
  }
  if (in.bad()) throw CsvError(file, lineno, "read error");
  if (!have_header) throw CsvError(file, 0, "no header line (file is empty or only comments)");
  if (t.rows.size() < opts.min_rows)
    throw CsvError(file, lineno,
                   "only " + std::to_string(t.rows.size()) + " data rows, at least " +
                       std::to_string(opts.min_rows) + " needed");
  return t;
}

}  // namespace

CsvTable read_csv(const std::filesystem::path& file, const CsvReadOptions& opts) {
  std::ifstream in(file);
  if (!in) throw CsvError(file, 0, "cannot open file");
  return read_stream(in, file, opts);
}

CsvTable parse_csv(const std::string& text, const std::filesystem::path& name,
                   const CsvReadOptions& opts) {
  std::istringstream in(text);
  return read_stream(in, name, opts);
}

std::string format_number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

std::string format_csv(const CsvTable& table, int significant_digits, NonFiniteCell non_finite) {
  std::ostringstream os;
  os << std::setprecision(significant_digits);
  for (const auto& [k, v] : table.metadata) {
    os << "# " << k;
    if (!v.empty()) os << ": " << v;
    os << '\n';
  }
  for (std::size_t i = 0; i < table.columns.size(); ++i)
    os << (i ? "," : "") << table.columns[i];
  os << '\n';
  for (const auto& r : table.rows) {
    for (std::size_t i = 0; i < r.size(); ++i) {
      if (i) os << ',';
      if (std::isfinite(r[i]) || non_finite == NonFiniteCell::text) os << r[i];
    }
    os << '\n';
  }
  return os.str();
}

void write_csv(const std::filesystem::path& file, const CsvTable& table, int significant_digits) {
  write_file_atomic(file, format_csv(table, significant_digits));
}

}  // namespace errsep::io

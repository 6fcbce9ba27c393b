#include "errsep/io/cnc/cnc_parameters.hpp"
#include "errsep/io/csv.hpp"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace errsep::io::cnc {
namespace {

// The whole of `s` as a finite number.
bool parse_double(const std::string& s, double* v) {
  std::size_t used = 0;
  try {
    *v = std::stod(s, &used);
  } catch (const std::exception&) {
    return false;
  }
  return used != 0 && used == s.size() && std::isfinite(*v);
}

}  // namespace

ParameterReader::ParameterReader(const CncParameters& params,
                                 const std::vector<std::pair<std::string, std::string>>& known,
                                 std::string format)
    : params_(params), format_(std::move(format)) {
  for (const auto& [key, value] : params_) {
    const bool ok = std::any_of(known.begin(), known.end(),
                                [&, k = key](const auto& p) { return p.first == k; });
    if (!ok) {
      std::string list;
      for (const auto& p : known)
        list += (list.empty() ? "" : ", ") + p.first;
      fail(key, "unknown parameter (known: " + (list.empty() ? std::string("none") : list) + ")");
    }
  }
}

void ParameterReader::fail(const std::string& key, const std::string& problem) const {
  throw std::invalid_argument(format_ + "." + key + ": " + problem);
}

std::string ParameterReader::text(const std::string& key, const std::string& dflt) const {
  const auto it = params_.find(key);
  return it == params_.end() ? dflt : it->second;
}

long ParameterReader::integer(const std::string& key, long dflt, long lo, long hi) const {
  const auto it = params_.find(key);
  if (it == params_.end()) return dflt;
  long v = 0;
  const std::string& s = it->second;
  const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || p != s.data() + s.size()) fail(key, "'" + s + "' is not an integer");
  if (v < lo || v > hi)
    fail(key,
         std::to_string(v) + " is out of range " + std::to_string(lo) + ".." + std::to_string(hi));
  return v;
}

double ParameterReader::number(const std::string& key, double dflt, double lo, double hi) const {
  const auto it = params_.find(key);
  if (it == params_.end()) return dflt;
  const std::string& s = it->second;
  double v = 0;
  if (!parse_double(s, &v)) fail(key, "'" + s + "' is not a number");
  if (v < lo || v > hi)
    fail(key,
         format_number(v) + " is out of range " + format_number(lo) + ".." + format_number(hi));
  return v;
}

std::vector<std::pair<std::string, std::string>> uniform_table_parameters(
    std::size_t default_max_points, const std::string& limit_note) {
  return {{"max_points", "the controller's point limit (" + limit_note + "; default " +
                             std::to_string(default_max_points) + ", 0 = none)"},
          {"step_mm",
           "node spacing in mm, must divide the measured range (default 0: chosen from the data "
           "and the point limit)"}};
}

core::UniformTableOptions uniform_table_options(const ParameterReader& r,
                                                std::size_t default_max_points) {
  core::UniformTableOptions o;
  o.max_points = static_cast<std::size_t>(
      r.integer("max_points", static_cast<long>(default_max_points), 0, 100000000));
  if (o.max_points == 1) r.fail("max_points", "1: a table needs at least 2 points (0 = no limit)");
  o.step_mm = r.number("step_mm", 0.0, 0.0, 1e9);
  return o;
}

std::string fixed(double v, int decimals) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
  std::string s(buf);
  if (!s.empty() && s[0] == '-' && s.find_first_not_of("-0.") == std::string::npos) s.erase(0, 1);
  return s;
}

std::string one_line(std::string s) {
  std::replace(s.begin(), s.end(), '\n', ' ');
  std::replace(s.begin(), s.end(), '\r', ' ');
  return s;
}

bool plain_name(const std::string& s) {
  if (s.empty()) return false;
  return std::all_of(s.begin(), s.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
  });
}

int axis_number(char axis) {
  const char u = static_cast<char>(std::toupper(static_cast<unsigned char>(axis)));
  return u == 'X' ? 1 : u == 'Y' ? 2 : 3;
}

char lower(char axis) {
  return static_cast<char>(std::tolower(static_cast<unsigned char>(axis)));
}

void read_fail(const std::string& name, std::size_t line, const std::string& problem) {
  throw std::runtime_error(name + (line ? ":" + std::to_string(line) : std::string()) + ": " +
                           problem);
}

double read_number(const std::string& s, const std::string& name, std::size_t line) {
  double v = 0;
  if (!parse_double(s, &v)) read_fail(name, line, "'" + s + "' is not a number");
  return v;
}

}  // namespace errsep::io::cnc

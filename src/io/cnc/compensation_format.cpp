#include "errsep/io/cnc/compensation_format.hpp"

#include <algorithm>
#include <cctype>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "errsep/io/cnc/beckhoff_crosscomp.hpp"
#include "errsep/io/cnc/heidenhain_com.hpp"
#include "errsep/io/cnc/linuxcnc_hal.hpp"
#include "errsep/io/cnc/sinumerik_cec.hpp"
#include "errsep/io/cnc/table_csv.hpp"

namespace errsep::io {

const char* to_string(CompensationFormat f) noexcept {
  switch (f) {
    case CompensationFormat::sinumerik_cec:
      return "sinumerik_cec";
    case CompensationFormat::linuxcnc_hal:
      return "linuxcnc_hal";
    case CompensationFormat::beckhoff_crosscomp:
      return "beckhoff_crosscomp";
    case CompensationFormat::heidenhain_com:
      return "heidenhain_com";
    case CompensationFormat::csv:
      return "csv";
  }
  return "unknown";
}

const std::vector<CompensationFormat>& all_compensation_formats() {
  static const std::vector<CompensationFormat> all = {
      CompensationFormat::sinumerik_cec, CompensationFormat::linuxcnc_hal,
      CompensationFormat::beckhoff_crosscomp, CompensationFormat::heidenhain_com,
      CompensationFormat::csv};
  return all;
}

std::optional<CompensationFormat> parse_compensation_format(std::string_view name) {
  for (const auto f : all_compensation_formats())
    if (name == to_string(f)) return f;
  return std::nullopt;
}

std::string compensation_format_names() {
  std::string s;
  for (const auto f : all_compensation_formats())
    s += (s.empty() ? "" : ", ") + std::string(to_string(f));
  return s;
}

const CompensationWriter& compensation_writer(CompensationFormat f) {
  switch (f) {
    case CompensationFormat::sinumerik_cec:
      return sinumerik_cec_writer();
    case CompensationFormat::linuxcnc_hal:
      return linuxcnc_hal_writer();
    case CompensationFormat::beckhoff_crosscomp:
      return beckhoff_crosscomp_writer();
    case CompensationFormat::heidenhain_com:
      return heidenhain_com_writer();
    case CompensationFormat::csv:
      return table_csv_writer();
  }
  throw std::invalid_argument("unknown compensation format");
}

std::optional<CompensationFormat> compensation_format_of(const std::filesystem::path& file) {
  std::string ext = file.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  for (const auto f : all_compensation_formats()) {
    std::string s = compensation_writer(f).suffix();
    std::transform(s.begin(), s.end(), s.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (s == ext) return f;
  }
  return std::nullopt;
}

ControllerTable read_compensation_file(const std::filesystem::path& file) {
  const auto f = compensation_format_of(file);
  if (!f) {
    std::string list;
    for (const auto g : all_compensation_formats())
      list += (list.empty() ? "" : ", ") + std::string(compensation_writer(g).suffix()) + " (" +
              to_string(g) + ")";
    throw std::runtime_error(file.string() + ": not a compensation table errsep reads (by its " +
                             "suffix: " + list + ")");
  }
  std::ifstream in(file, std::ios::binary);
  if (!in) throw std::runtime_error(file.string() + ": cannot open the compensation table");
  std::ostringstream ss;
  ss << in.rdbuf();
  return compensation_writer(*f).read(ss.str(), file.string());
}

}  // namespace errsep::io

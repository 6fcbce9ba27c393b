#include "errsep/io/machine_axes_metadata.hpp"
#include "errsep/io/csv.hpp"

#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace errsep::io {
namespace {

const std::string* find(const Metadata& md, const std::string& key) {
  for (const auto& [k, v] : md)
    if (k == key) return &v;
  return nullptr;
}

int sign_of(const std::string& key, const std::string& v) {
  if (v == "1" || v == "+1" || v == "+") return 1;
  if (v == "-1" || v == "-") return -1;
  throw std::invalid_argument("metadata " + key + ": '" + v + "' is not +1 or -1");
}

}  // namespace

Metadata machine_axes_metadata(const core::MachineAxes& a) {
  return {{"axis", std::string(1, a.input_axis)},
          {"straightness_direction", std::string(1, a.output_axis)},
          {"slide_start_mm", format_number(a.slide_start_mm)},
          {"scan_direction", a.scan_direction > 0 ? "+1" : "-1"},
          {"reading_sign", a.reading_sign > 0 ? "+1" : "-1"}};
}

std::optional<core::MachineAxes> machine_axes_from_metadata(const Metadata& md) {
  const std::string* start = find(md, "slide_start_mm");
  const std::string* dir = find(md, "scan_direction");
  const std::string* sign = find(md, "reading_sign");
  if (!start || !dir || !sign) return std::nullopt;
  core::MachineAxes a;
  if (const std::string* v = find(md, "axis")) {
    a.input_axis = core::parse_linear_axis(*v);
    if (!a.input_axis) throw std::invalid_argument("metadata axis: '" + *v + "' is not X, Y or Z");
  }
  if (const std::string* v = find(md, "straightness_direction")) {
    a.output_axis = core::parse_linear_axis(*v);
    if (!a.output_axis)
      throw std::invalid_argument("metadata straightness_direction: '" + *v + "' is not X, Y or Z");
  }
  std::size_t used = 0;
  try {
    a.slide_start_mm = std::stod(*start, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != start->size() || !std::isfinite(a.slide_start_mm))
    throw std::invalid_argument("metadata slide_start_mm: '" + *start + "' is not a number");
  a.scan_direction = sign_of("scan_direction", *dir);
  a.reading_sign = sign_of("reading_sign", *sign);
  std::string why;
  if (!a.is_valid(&why)) throw std::invalid_argument("metadata: " + why);
  return a;
}

}  // namespace errsep::io

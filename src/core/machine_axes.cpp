#include "errsep/core/machine_axes.hpp"

#include <cctype>
#include <cmath>

#include "errsep/core/iso230.hpp"

namespace errsep::core {

char parse_linear_axis(const std::string& s) {
  if (s.size() != 1) return 0;
  const char u = static_cast<char>(std::toupper(static_cast<unsigned char>(s[0])));
  return (u == 'X' || u == 'Y' || u == 'Z') ? u : 0;
}

std::string MachineAxes::symbol() const {
  return straightness_symbol(input_axis, output_axis);
}

bool MachineAxes::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!parse_linear_axis(std::string(1, input_axis)))
    return fail(std::string("input_axis '") + input_axis + "' is not X, Y or Z");
  if (!parse_linear_axis(std::string(1, output_axis)))
    return fail(std::string("output_axis '") + output_axis + "' is not X, Y or Z");
  if (std::toupper(static_cast<unsigned char>(input_axis)) ==
      std::toupper(static_cast<unsigned char>(output_axis)))
    return fail(std::string("input_axis and output_axis are both ") + input_axis +
                ": a straightness error lies across the moving axis");
  if (!std::isfinite(slide_start_mm))
    return fail("slide_start_mm = " + std::to_string(slide_start_mm) + " must be finite");
  if (scan_direction != 1 && scan_direction != -1)
    return fail("scan_direction = " + std::to_string(scan_direction) + " must be +1 or -1");
  if (reading_sign != 1 && reading_sign != -1)
    return fail("reading_sign = " + std::to_string(reading_sign) + " must be +1 or -1");
  return true;
}

}  // namespace errsep::core

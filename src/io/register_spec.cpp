#include "errsep/io/register_spec.hpp"

#include <cmath>

namespace errsep::io {

bool RegisterSpec::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (unit_id < 0 || unit_id > 247)
    return fail("unit_id = " + std::to_string(unit_id) + " must be in 0..247");
  if (address < 0 || address + word_count() - 1 > 65535)
    return fail("address = " + std::to_string(address) + " must be in 0.." +
                std::to_string(65536 - word_count()));
  if (!std::isfinite(scale) || scale == 0.0)
    return fail("scale = " + std::to_string(scale) + " must be finite and non-zero");
  if (!std::isfinite(offset)) return fail("offset must be finite");
  return true;
}

const char* to_string(RegisterKind k) noexcept {
  switch (k) {
    case RegisterKind::input:
      return "input";
    case RegisterKind::holding:
      return "holding";
    case RegisterKind::coil:
      return "coil";
  }
  return "unknown";
}

const char* to_string(RegisterType t) noexcept {
  switch (t) {
    case RegisterType::int16:
      return "int16";
    case RegisterType::uint16:
      return "uint16";
    case RegisterType::int32:
      return "int32";
    case RegisterType::float32:
      return "float32";
  }
  return "unknown";
}

const char* to_string(WordOrder w) noexcept {
  switch (w) {
    case WordOrder::big:
      return "big";
    case WordOrder::little:
      return "little";
  }
  return "unknown";
}

std::optional<RegisterKind> parse_register_kind(std::string_view s) {
  if (s == "input") return RegisterKind::input;
  if (s == "holding") return RegisterKind::holding;
  if (s == "coil") return RegisterKind::coil;
  return std::nullopt;
}

std::optional<RegisterType> parse_register_type(std::string_view s) {
  if (s == "int16") return RegisterType::int16;
  if (s == "uint16") return RegisterType::uint16;
  if (s == "int32") return RegisterType::int32;
  if (s == "float32") return RegisterType::float32;
  return std::nullopt;
}

std::optional<WordOrder> parse_word_order(std::string_view s) {
  if (s == "big") return WordOrder::big;
  if (s == "little") return WordOrder::little;
  return std::nullopt;
}

}  // namespace errsep::io

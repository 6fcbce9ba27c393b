#include "errsep/acq/register_map.hpp"

#include <bit>
#include <cmath>
#include <limits>

namespace errsep::acq {
namespace {

std::uint32_t join(const RegisterSpec& spec, const std::uint16_t* w) noexcept {
  const std::uint32_t first = w[0], second = w[1];
  return spec.word_order == WordOrder::big ? (first << 16) | second : (second << 16) | first;
}

void split(const RegisterSpec& spec, std::uint32_t v, std::uint16_t* w) noexcept {
  const auto hi = static_cast<std::uint16_t>(v >> 16);
  const auto lo = static_cast<std::uint16_t>(v & 0xFFFFu);
  if (spec.word_order == WordOrder::big) {
    w[0] = hi;
    w[1] = lo;
  } else {
    w[0] = lo;
    w[1] = hi;
  }
}

// Rounds and saturates to [lo, hi]; `ok` false when saturated or NaN.
template <typename T>
T to_int(double raw, bool& ok) noexcept {
  constexpr double lo = static_cast<double>(std::numeric_limits<T>::min());
  constexpr double hi = static_cast<double>(std::numeric_limits<T>::max());
  if (std::isnan(raw)) {
    ok = false;
    return 0;
  }
  const double r = std::nearbyint(raw);
  if (r < lo) {
    ok = false;
    return std::numeric_limits<T>::min();
  }
  if (r > hi) {
    ok = false;
    return std::numeric_limits<T>::max();
  }
  ok = true;
  return static_cast<T>(r);
}

}  // namespace

double decode_raw(const RegisterSpec& spec, const std::uint16_t* words) noexcept {
  if (spec.kind == RegisterKind::coil) return words[0] != 0 ? 1.0 : 0.0;
  switch (spec.type) {
    case RegisterType::int16:
      return static_cast<double>(static_cast<std::int16_t>(words[0]));
    case RegisterType::uint16:
      return static_cast<double>(words[0]);
    case RegisterType::int32:
      return static_cast<double>(static_cast<std::int32_t>(join(spec, words)));
    case RegisterType::float32:
      return static_cast<double>(std::bit_cast<float>(join(spec, words)));
  }
  return std::numeric_limits<double>::quiet_NaN();
}

bool encode_raw(const RegisterSpec& spec, double raw, std::uint16_t* words) noexcept {
  bool ok = true;
  if (spec.kind == RegisterKind::coil) {
    words[0] = (raw != 0.0 && !std::isnan(raw)) ? 1 : 0;
    return !std::isnan(raw);
  }
  switch (spec.type) {
    case RegisterType::int16:
      words[0] = static_cast<std::uint16_t>(to_int<std::int16_t>(raw, ok));
      return ok;
    case RegisterType::uint16:
      words[0] = to_int<std::uint16_t>(raw, ok);
      return ok;
    case RegisterType::int32:
      split(spec, static_cast<std::uint32_t>(to_int<std::int32_t>(raw, ok)), words);
      return ok;
    case RegisterType::float32: {
      const auto f = static_cast<float>(raw);
      split(spec, std::bit_cast<std::uint32_t>(f), words);
      return std::isfinite(f) || std::isinf(raw);  // NaN, or overflow of a finite value: false
    }
  }
  return false;
}

bool encode(const RegisterSpec& spec, double value, std::uint16_t* words) noexcept {
  if (spec.kind == RegisterKind::coil) return encode_raw(spec, value, words);
  return encode_raw(spec, (value - spec.offset) / spec.scale, words);
}

}  // namespace errsep::acq

#pragma once
// Decoding and encoding of register values (pure: no libmodbus, no I/O).  The drivers decode the
// words a device returned; the device simulator and tests encode.
//
//   physical = raw · scale + offset          (µm for sensors, mm for stage positions)
//
// 32-bit values occupy two registers; WordOrder::big puts the high word at the lower address
// (libmodbus "abcd"), WordOrder::little the low word (libmodbus "cdab").
#include <cstdint>

#include "errsep/io/register_spec.hpp"

namespace errsep::acq {

using io::RegisterKind;
using io::RegisterSpec;
using io::RegisterType;
using io::WordOrder;

/// The raw value of the register(s) as the spec's data type (before scale and offset).  For a
/// coil, words[0] != 0 gives 1.  float32 NaN/Inf are returned as they are.  Real-time safe.
double decode_raw(const RegisterSpec& spec, const std::uint16_t* words) noexcept;

/// raw · scale + offset.  Real-time safe.
inline double decode(const RegisterSpec& spec, const std::uint16_t* words) noexcept {
  return decode_raw(spec, words) * spec.scale + spec.offset;
}

/// Writes (value − offset)/scale into spec.word_count() words: integers rounded to nearest and
/// saturated at the type's limits.  Returns false when the value was not representable (NaN, or
/// saturated), true otherwise.  Real-time safe.
bool encode(const RegisterSpec& spec, double value, std::uint16_t* words) noexcept;

/// Writes a raw value (already in the data type's units) into words; same rules as encode().
bool encode_raw(const RegisterSpec& spec, double raw, std::uint16_t* words) noexcept;

}  // namespace errsep::acq

#pragma once
// Where and how a value lives in a Modbus device: the pure description read from the machine
// config.  Decoding/encoding is in errsep/acq/register_map.hpp; this header is in io only because
// the config layer (io) must describe registers and io may not depend on acq.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace errsep::io {

/// Modbus object kind.  Coils are single bits (stage stop command); the rest are 16-bit words.
enum class RegisterKind : std::uint8_t { input, holding, coil };

/// Data type of the value held in one (16-bit types) or two (32-bit types) registers.
enum class RegisterType : std::uint8_t { int16, uint16, int32, float32 };

/// Order of the two 16-bit words of a 32-bit value.  big: high word at the lower address
/// (Modbus convention, libmodbus "abcd"); little: low word first (word swap, libmodbus "cdab").
/// The bytes within each word are always big-endian on the wire.
enum class WordOrder : std::uint8_t { big, little };

struct RegisterSpec {
  int unit_id = 1;  ///< Modbus unit (slave) id, 0..247
  int address = 0;  ///< 0-based register (or coil) address, 0..65535
  RegisterKind kind = RegisterKind::input;
  RegisterType type = RegisterType::float32;
  WordOrder word_order = WordOrder::big;
  /// physical = raw·scale + offset, in the unit of the consumer (µm for sensors, mm for stages).
  double scale = 1.0;
  double offset = 0.0;

  /// Number of 16-bit registers occupied (1 for int16/uint16 and coils, 2 for int32/float32).
  constexpr int word_count() const noexcept {
    return (kind == RegisterKind::coil || type == RegisterType::int16 ||
            type == RegisterType::uint16)
               ? 1
               : 2;
  }
  /// True when usable; otherwise `why` names the field, its value and the constraint.
  bool is_valid(std::string* why = nullptr) const;
};

// Names as spelled in the config file ("input", "float32", "big", ...).
const char* to_string(RegisterKind k) noexcept;
const char* to_string(RegisterType t) noexcept;
const char* to_string(WordOrder w) noexcept;
std::optional<RegisterKind> parse_register_kind(std::string_view s);
std::optional<RegisterType> parse_register_type(std::string_view s);
std::optional<WordOrder> parse_word_order(std::string_view s);

}  // namespace errsep::io

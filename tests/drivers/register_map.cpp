// Pure decode/encode of register values: every data type and word order against bit patterns
// written out by hand (IEEE 754 and two's complement), so a swapped word or a sign error shows.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <limits>

#include "errsep/acq/register_map.hpp"

using errsep::acq::decode;
using errsep::acq::decode_raw;
using errsep::acq::encode;
using errsep::acq::RegisterKind;
using errsep::acq::RegisterSpec;
using errsep::acq::RegisterType;
using errsep::acq::WordOrder;

namespace {
RegisterSpec spec(RegisterType t, WordOrder w = WordOrder::big, double scale = 1.0,
                  double offset = 0.0) {
  RegisterSpec s;
  s.type = t;
  s.word_order = w;
  s.scale = scale;
  s.offset = offset;
  return s;
}
}  // namespace

TEST_CASE("int16 and uint16 decode two's complement and unsigned") {
  const std::uint16_t w[1] = {0xFFFE};
  CHECK(decode_raw(spec(RegisterType::int16), w) == -2.0);
  CHECK(decode_raw(spec(RegisterType::uint16), w) == 65534.0);
  const std::uint16_t m[1] = {0x8000};
  CHECK(decode_raw(spec(RegisterType::int16), m) == -32768.0);
  CHECK(decode_raw(spec(RegisterType::uint16), m) == 32768.0);
  // 16-bit types ignore the word order.
  CHECK(decode_raw(spec(RegisterType::int16, WordOrder::little), w) == -2.0);
}

TEST_CASE("int32 in both word orders") {
  // -123456789 = 0xF8A432EB
  const std::uint16_t big[2] = {0xF8A4, 0x32EB};
  const std::uint16_t little[2] = {0x32EB, 0xF8A4};
  CHECK(decode_raw(spec(RegisterType::int32, WordOrder::big), big) == -123456789.0);
  CHECK(decode_raw(spec(RegisterType::int32, WordOrder::little), little) == -123456789.0);
  // The wrong order gives a different number: the test would catch a swap.
  CHECK(decode_raw(spec(RegisterType::int32, WordOrder::little), big) != -123456789.0);
  // 305419896 = 0x12345678
  const std::uint16_t p[2] = {0x1234, 0x5678};
  CHECK(decode_raw(spec(RegisterType::int32, WordOrder::big), p) == 305419896.0);
  CHECK(decode_raw(spec(RegisterType::int32, WordOrder::little), p) == 1450709556.0);  // 0x56781234
}

TEST_CASE("float32 in both word orders") {
  // 1.5f = 0x3FC00000, -2.25f = 0xC0100000, 123.456f = 0x42F6E979
  const std::uint16_t a_big[2] = {0x3FC0, 0x0000};
  const std::uint16_t a_little[2] = {0x0000, 0x3FC0};
  CHECK(decode_raw(spec(RegisterType::float32, WordOrder::big), a_big) == 1.5);
  CHECK(decode_raw(spec(RegisterType::float32, WordOrder::little), a_little) == 1.5);
  const std::uint16_t b[2] = {0xC010, 0x0000};
  CHECK(decode_raw(spec(RegisterType::float32, WordOrder::big), b) == -2.25);
  const std::uint16_t c_little[2] = {0xE979, 0x42F6};
  CHECK(decode_raw(spec(RegisterType::float32, WordOrder::little), c_little) ==
        static_cast<double>(123.456f));
  const std::uint16_t nan[2] = {0x7FC0, 0x0000};
  CHECK(std::isnan(decode_raw(spec(RegisterType::float32), nan)));
}

TEST_CASE("scale and offset give physical units") {
  const std::uint16_t w[1] = {0xFFF6};  // int16 -10
  CHECK(decode(spec(RegisterType::int16, WordOrder::big, 0.1, 5.0), w) == Approx(4.0));
  const std::uint16_t u[1] = {40000};  // uint16 40000 · 0.05 − 1000 = 1000
  CHECK(decode(spec(RegisterType::uint16, WordOrder::big, 0.05, -1000.0), u) == Approx(1000.0));
  const std::uint16_t n[2] = {0x0001, 0xE240};  // int32 123456 nm → 123.456 µm
  CHECK(decode(spec(RegisterType::int32, WordOrder::big, 0.001), n) == Approx(123.456));
}

TEST_CASE("encode writes the same bit patterns and round-trips") {
  std::uint16_t w[2] = {0, 0};
  REQUIRE(encode(spec(RegisterType::int32, WordOrder::little), -123456789.0, w));
  CHECK(w[0] == 0x32EB);
  CHECK(w[1] == 0xF8A4);
  REQUIRE(encode(spec(RegisterType::float32, WordOrder::big), -2.25, w));
  CHECK(w[0] == 0xC010);
  CHECK(w[1] == 0x0000);
  REQUIRE(encode(spec(RegisterType::int16, WordOrder::big, 0.1), -12.34, w));
  CHECK(w[0] == static_cast<std::uint16_t>(-123));  // rounded to the nearest count
  for (auto t :
       {RegisterType::int16, RegisterType::uint16, RegisterType::int32, RegisterType::float32}) {
    for (auto o : {WordOrder::big, WordOrder::little}) {
      const RegisterSpec s = spec(t, o, 0.01, 100.0);
      for (double v : {100.0, 150.25, 327.0}) {
        std::uint16_t x[2] = {0, 0};
        REQUIRE(encode(s, v, x));
        CHECK(decode(s, x) == Approx(v).margin(0.005));
      }
    }
  }
}

TEST_CASE("encode saturates and reports values it cannot represent") {
  std::uint16_t w[2] = {0, 0};
  CHECK_FALSE(encode(spec(RegisterType::int16), 40000.0, w));
  CHECK(static_cast<std::int16_t>(w[0]) == 32767);
  CHECK_FALSE(encode(spec(RegisterType::uint16), -1.0, w));
  CHECK(w[0] == 0);
  CHECK_FALSE(encode(spec(RegisterType::int32), 3e9, w));
  CHECK_FALSE(encode(spec(RegisterType::int16), std::nan(""), w));
  CHECK_FALSE(encode(spec(RegisterType::float32), std::nan(""), w));
  CHECK_FALSE(encode(spec(RegisterType::float32), 1e39, w));  // overflows float
}

TEST_CASE("coils decode to 0/1 and specs validate") {
  RegisterSpec c;
  c.kind = RegisterKind::coil;
  const std::uint16_t on[1] = {1}, off[1] = {0};
  CHECK(decode(c, on) == 1.0);
  CHECK(decode(c, off) == 0.0);
  CHECK(c.word_count() == 1);
  RegisterSpec s = spec(RegisterType::float32);
  CHECK(s.word_count() == 2);
  std::string why;
  CHECK(s.is_valid(&why));
  s.scale = 0.0;
  CHECK_FALSE(s.is_valid(&why));
  CHECK(why.find("scale") != std::string::npos);
  s.scale = 1.0;
  s.address = 65535;  // a 2-word value cannot start at the last address
  CHECK_FALSE(s.is_valid(&why));
  CHECK(why.find("address") != std::string::npos);
}

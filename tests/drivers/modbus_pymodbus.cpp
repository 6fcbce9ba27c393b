// errsep's Modbus driver against a server not written here: Debian's python3-pymodbus 3.0
// (tests/support/pymodbus_server.py), started and stopped by a ctest fixture
// (tests/drivers/modbus_pymodbus.cmake).  The values were encoded by pymodbus's own payload
// builder; errsep must decode every data type and word order to the same numbers.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <optional>
#include <string>

#include "errsep/acq/register_map.hpp"
#include "errsep/drivers/modbus_bus.hpp"
#include "errsep/drivers/modbus_sensor.hpp"

using namespace errsep;
using acq::IoStatus;

namespace {

/// The server's port, or nullopt after printing why the test is skipped.
std::optional<int> server_port() {
  const char* dir = std::getenv("ERRSEP_PYMODBUS_DIR");
  if (!dir) {
    FAIL(
        "ERRSEP_PYMODBUS_DIR is not set: run this test through ctest, whose fixture starts "
        "the pymodbus server (tests/drivers/modbus_pymodbus.cmake)");
  }
  std::ifstream in(std::string(dir) + "/port");
  std::string word;
  if (!(in >> word)) FAIL("no port file in " << dir << ": the fixture did not start the server");
  if (word == "skip") {
    std::string reason;
    std::getline(in, reason);
    // In CI the package list (cmake/debian-packages.txt) installs pymodbus and what it imports;
    // a skip there means the list is broken (a stop once passed CI with every case skipped for
    // a missing python3-serial), so it fails instead of skipping.
    if (std::getenv("CI") != nullptr)
      FAIL("CI is set but the pymodbus server did not start:" << reason);
    WARN("SKIPPED:" << reason);  // ctest's SKIP_REGULAR_EXPRESSION marks the test skipped
    return std::nullopt;
  }
  return std::stoi(word);
}

io::BusConfig bus_config(int port) {
  io::BusConfig b;
  b.name = "pymodbus";
  b.kind = io::BusKind::tcp;
  b.host = "127.0.0.1";
  b.port = port;
  b.response_timeout_ms = 1000;  // Python answers in ~1 ms; be generous on a loaded machine
  b.retries = 0;
  return b;
}

io::RegisterSpec reg(int address, io::RegisterType t, io::WordOrder w,
                     io::RegisterKind k = io::RegisterKind::input, int unit = 1) {
  io::RegisterSpec s;
  s.unit_id = unit;
  s.address = address;
  s.kind = k;
  s.type = t;
  s.word_order = w;
  return s;
}

struct Expect {
  int address;
  io::RegisterType type;
  io::WordOrder order;
  double value;  // as pymodbus_server.py encodes it (floats rounded to float32)
};

const Expect kExpected[] = {
    {0, io::RegisterType::int16, io::WordOrder::big, -1234},
    {1, io::RegisterType::uint16, io::WordOrder::big, 54321},
    {2, io::RegisterType::int32, io::WordOrder::big, -123456789},
    {4, io::RegisterType::int32, io::WordOrder::little, -123456789},
    {6, io::RegisterType::float32, io::WordOrder::big, static_cast<double>(123.456f)},
    {8, io::RegisterType::float32, io::WordOrder::little, -0.015625},
    {10, io::RegisterType::int32, io::WordOrder::big, 305419896},
    {12, io::RegisterType::int32, io::WordOrder::little, 305419896},
    {14, io::RegisterType::float32, io::WordOrder::big, -98765.4375},
    {16, io::RegisterType::float32, io::WordOrder::little, 98765.4375},
};

void check_all(drivers::ModbusBus& bus, io::RegisterKind kind, int unit, bool negated) {
  for (const Expect& e : kExpected) {
    std::uint16_t w[2] = {0, 0};
    const io::RegisterSpec s = reg(e.address, e.type, e.order, kind, unit);
    INFO(io::to_string(kind) << " register " << e.address << " unit " << unit << " "
                             << io::to_string(e.type) << " " << io::to_string(e.order));
    REQUIRE(bus.read(s, w) == IoStatus::ok);
    double want = e.value;
    if (negated) want = e.type == io::RegisterType::uint16 ? 12345.0 : -e.value;
    CHECK(acq::decode(s, w) == want);  // exact: these values are representable
  }
}

}  // namespace

TEST_CASE("every data type and word order, input registers") {
  const auto port = server_port();
  if (!port) return;
  drivers::ModbusBus bus(bus_config(*port));
  bus.configure();
  check_all(bus, io::RegisterKind::input, 1, false);
  CHECK(bus.counters().ok == std::size(kExpected));
}

TEST_CASE("every data type and word order, holding registers") {
  const auto port = server_port();
  if (!port) return;
  drivers::ModbusBus bus(bus_config(*port));
  bus.configure();
  check_all(bus, io::RegisterKind::holding, 1, false);
}

TEST_CASE("unit ids select the device: unit 7 serves the negated values") {
  const auto port = server_port();
  if (!port) return;
  drivers::ModbusBus bus(bus_config(*port));
  bus.configure();
  check_all(bus, io::RegisterKind::input, 7, true);
}

TEST_CASE("a sensor applies scale, offset and the measuring range") {
  const auto port = server_port();
  if (!port) return;
  drivers::ModbusBus bus(bus_config(*port));
  bus.configure();
  io::SensorConfig c;
  c.name = "nm_counter";
  c.bus = "pymodbus";
  c.reg = reg(4, io::RegisterType::int32, io::WordOrder::little);
  c.reg.scale = 1e-6;  // nm → mm-ish scale, to land in range: −123.456789
  c.reg.offset = 100.0;
  c.range_min_um = -100.0;
  c.range_max_um = 100.0;
  drivers::ModbusSensor s(c, bus, 3);
  s.configure();
  acq::Sample out;
  REQUIRE(s.read(out) == IoStatus::ok);
  CHECK(out.value == Approx(-123456789 * 1e-6 + 100.0).epsilon(1e-12));
  CHECK(out.channel == 3);
  c.range_max_um = -30.0;  // now the same reading is beyond the range
  drivers::ModbusSensor narrow(c, bus, 4);
  narrow.configure();
  CHECK(narrow.read(out) == IoStatus::out_of_range);
  CHECK(out.value == Approx(-23.456789));
}

TEST_CASE("writes: holding registers and coils are stored by the foreign server") {
  const auto port = server_port();
  if (!port) return;
  drivers::ModbusBus bus(bus_config(*port));
  bus.configure();
  for (auto order : {io::WordOrder::big, io::WordOrder::little}) {
    const io::RegisterSpec t = reg(20, io::RegisterType::float32, order, io::RegisterKind::holding);
    std::uint16_t w[2] = {0, 0};
    const double target = order == io::WordOrder::big ? 12.5 : -7.25;
    REQUIRE(acq::encode(t, target, w));
    REQUIRE(bus.write(t, w) == IoStatus::ok);
    std::uint16_t back[2] = {0, 0};
    REQUIRE(bus.read(t, back) == IoStatus::ok);
    CHECK(acq::decode(t, back) == target);
  }
  io::RegisterSpec coil;
  coil.kind = io::RegisterKind::coil;
  coil.address = 5;
  std::uint16_t b[1] = {0};
  REQUIRE(bus.read(coil, b) == IoStatus::ok);
  CHECK(b[0] == 0);
  REQUIRE(bus.write_coil(coil, true) == IoStatus::ok);
  REQUIRE(bus.read(coil, b) == IoStatus::ok);
  CHECK(b[0] == 1);
  coil.address = 0;
  REQUIRE(bus.read(coil, b) == IoStatus::ok);
  CHECK(b[0] == 1);
}

TEST_CASE("an address the server does not have gives its exception, not a value") {
  const auto port = server_port();
  if (!port) return;
  drivers::ModbusBus bus(bus_config(*port));
  bus.configure();
  std::uint16_t w[2] = {0xAAAA, 0xAAAA};
  CHECK(bus.read(reg(500, io::RegisterType::float32, io::WordOrder::big), w) ==
        IoStatus::device_exception);
  CHECK(bus.counters().last_exception_code == 2);  // illegal data address
  CHECK(bus.counters().disconnects == 0);
  // The link is still usable.
  CHECK(bus.read(reg(0, io::RegisterType::int16, io::WordOrder::big), w) == IoStatus::ok);
}

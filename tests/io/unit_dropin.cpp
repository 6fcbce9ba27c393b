// The systemd drop-in for the daemon's network: exactly the Modbus TCP hosts of the config and a
// non-loopback register-map address, nothing for loopback-only configs.
#include <catch2/catch.hpp>
#include <string>

#include "errsep/io/machine_config.hpp"
#include "errsep/io/unit_dropin.hpp"
#include "support/support.hpp"

using namespace errsep::io;

namespace {
std::size_t count(const std::string& s, const std::string& needle) {
  std::size_t n = 0;
  for (auto p = s.find(needle); p != std::string::npos; p = s.find(needle, p + 1))
    ++n;
  return n;
}
}  // namespace

TEST_CASE("drop-in of the example machine: its drive's address, nothing else") {
  const auto cfg =
      load_machine_config(errsep::test::source_dir() / "config" / "machine-example.toml");
  const std::string d = unit_network_dropin(cfg, "127.0.0.1");
  INFO(d);
  CHECK(d.find("[Service]\n") != std::string::npos);
  CHECK(d.find("IPAddressAllow=192.168.10.20\n") != std::string::npos);
  CHECK(count(d, "\nIPAddressAllow=") == 1);  // the RTU line and the loopback map need none
  CHECK(d.find("Modbus TCP bus 'drive'") != std::string::npos);
}

TEST_CASE("drop-in: a register map for the cell controller, host names, loopback only") {
  auto cfg = load_machine_config(errsep::test::source_dir() / "config" / "machine-example.toml");
  std::string d = unit_network_dropin(cfg, "10.0.0.5");
  CHECK(d.find("IPAddressAllow=10.0.0.5\n") != std::string::npos);
  CHECK(count(d, "\nIPAddressAllow=") == 2);
  cfg.buses[1].host = "drive.local";
  d = unit_network_dropin(cfg, "127.0.0.1");
  CHECK(d.find("'drive.local' is a host name") != std::string::npos);
  CHECK(count(d, "\nIPAddressAllow=") == 0);
  const auto sim = load_machine_config(errsep::test::source_dir() / "config" / "simulator.toml");
  d = unit_network_dropin(sim, "127.0.0.1");
  CHECK(d.find("no drop-in needed") != std::string::npos);
  CHECK(d.find("[Service]") == std::string::npos);
}

// config/errsep.service passes `systemd-analyze verify` (skipped with a message where
// systemd-analyze is absent).  The unit names /usr/local/bin/errsep-daemon, which verify checks
// exists: the copy verified here points at the built binary instead, nothing else changed.
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include "support/support.hpp"

using namespace errsep;

namespace {
std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}
std::string find_analyze() {
  for (const char* p : {"/usr/bin/systemd-analyze", "/bin/systemd-analyze"})
    if (std::filesystem::exists(p)) return p;
  return {};
}
}  // namespace

TEST_CASE("the systemd unit has the hardening the issue asks for") {
  const std::string u = slurp(test::source_dir() / "config/errsep.service");
  for (const char* key : {"Type=notify", "WatchdogSec=", "DynamicUser=yes", "ProtectSystem=strict",
                          "StateDirectory=errsep", "NoNewPrivileges=yes",
                          "CapabilityBoundingSet=", "DevicePolicy=closed",
                          "DeviceAllow=char-gpiochip", "DeviceAllow=char-ttyUSB",
                          "IPAddressDeny=any", "IPAddressAllow=localhost", "ExecReload="}) {
    INFO(key);
    CHECK(u.find(key) != std::string::npos);
  }
  // The sampler may use SCHED_FIFO: the unit must not forbid it (NOTES.md).
  CHECK(u.find("RestrictRealtime=yes") == std::string::npos);
  // READY=1 does not wait for the devices (daemon_fault: within 5 s with the machine off), so a
  // finite start timeout well above that bounds a hung start without restarting a daemon that
  // only waits for its machine.
  const auto ts = u.find("\nTimeoutStartSec=");
  REQUIRE(ts != std::string::npos);
  const std::string v = u.substr(ts + 17, u.find('\n', ts + 1) - ts - 17);
  INFO("TimeoutStartSec=" << v);
  REQUIRE(v.find_first_not_of("0123456789") == std::string::npos);
  CHECK(std::stoi(v) >= 30);
  CHECK(u.find("Restart=on-failure") != std::string::npos);
}

TEST_CASE("systemd-analyze verify config/errsep.service") {
  const std::string analyze = find_analyze();
  if (analyze.empty()) {
    std::cout << "SKIPPED: systemd-analyze not installed; cannot verify config/errsep.service\n";
    return;
  }
  test::TempDir tmp;
  std::string unit = slurp(test::source_dir() / "config/errsep.service");
  const std::string installed = "/usr/local/bin/errsep-daemon";
  const auto pos = unit.find(installed);
  REQUIRE(pos != std::string::npos);
  unit.replace(pos, installed.size(), test::app_path("daemon").string());
  const auto copy = tmp / "errsep.service";
  std::ofstream(copy) << unit;
  std::string out;
  const int rc = test::run_command(analyze + " verify " + copy.string(), &out);
  INFO(out);
  CHECK(rc == 0);
  // verify warns about unknown or misplaced keys without failing: none are accepted here.
  CHECK(out.find("errsep.service") == std::string::npos);
}

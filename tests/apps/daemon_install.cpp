// `cmake --install <build> --prefix <tmp>` (a prefix with a space, as a stress) puts every errsep-*
// app in bin/ (executable, and it runs), the systemd unit in lib/systemd/system/ with ExecStart=
// naming the installed daemon (the unit is written at install time for the actual prefix,
// apps/daemon/install_unit.cmake), and the example configs in share/errsep/config/ (the machine
// example loads).  Where systemd-analyze exists, the installed unit passes `systemd-analyze verify`
// as installed, unmodified.
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include "errsep/io/machine_config.hpp"
#include "errsep/version.hpp"
#include "support/support.hpp"

using namespace errsep;
namespace fs = std::filesystem;

namespace {
std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}
bool executable(const fs::path& p) {
  const auto perms = fs::status(p).permissions();
  return fs::is_regular_file(p) && (perms & fs::perms::owner_exec) != fs::perms::none &&
         (perms & fs::perms::others_exec) != fs::perms::none;
}
std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> v;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, sep))
    if (!item.empty()) v.push_back(item);
  return v;
}
/// Value of the first "Key=" line of a unit file.
std::string unit_value(const std::string& unit, const std::string& key) {
  std::istringstream is(unit);
  std::string line;
  while (std::getline(is, line))
    if (line.rfind(key + "=", 0) == 0) return line.substr(key.size() + 1);
  return {};
}
}  // namespace

TEST_CASE("cmake --install puts binaries, the unit and the example configs in place") {
  test::TempDir tmp;
  const fs::path prefix = tmp / "prefix with space";
  std::string out;
  const int rc =
      test::run_command(std::string("'") + ERRSEP_CMAKE_COMMAND + "' --install '" +
                            test::binary_dir().string() + "' --prefix '" + prefix.string() + "'",
                        &out);
  INFO(out);
  REQUIRE(rc == 0);

  const fs::path bin = prefix / ERRSEP_INSTALL_BINDIR;
  const auto apps = split(ERRSEP_INSTALLED_APPS, ',');
  REQUIRE(apps.size() >= 2);
  for (const auto& app : apps) {
    INFO(app);
    CHECK(executable(bin / app));
  }
  // Nothing but errsep-* apps in bin/.
  for (const auto& e : fs::directory_iterator(bin))
    CHECK(e.path().filename().string().rfind("errsep-", 0) == 0);

  // The installed daemon runs from its new place (errsep libraries static, or shared and installed
  // under lib/ with a relative RUNPATH; system shared libs).
  std::string ver;
  REQUIRE(test::run_command("'" + (bin / "errsep-daemon").string() + "' --version", &ver) == 0);
  CHECK_THAT(ver, Catch::Contains(std::string(errsep::kVersion)));

  // The unit: ExecStart= is the installed binary, executable.
  const fs::path unit_path = prefix / "lib/systemd/system/errsep.service";
  REQUIRE(fs::is_regular_file(unit_path));
  const std::string unit = slurp(unit_path);
  const std::string exec = unit_value(unit, "ExecStart");
  REQUIRE_FALSE(exec.empty());
  // The command is quoted when the prefix has white space (systemd.service(5)).
  const std::string exec_bin =
      exec[0] == '"' ? exec.substr(1, exec.find('"', 1) - 1) : exec.substr(0, exec.find(' '));
  CHECK(exec_bin == (bin / "errsep-daemon").string());
  CHECK(executable(exec_bin));
  CHECK(unit.find("/usr/local/") == std::string::npos);  // every path follows the prefix
  // Documentation= is a URI: the space of the prefix percent-encoded, '%' doubled for systemd.
  std::string doc_uri = (prefix / ERRSEP_INSTALL_DATADIR / "errsep/config").string();
  for (std::size_t p = doc_uri.find(' '); p != std::string::npos; p = doc_uri.find(' ', p))
    doc_uri.replace(p, 1, "%%20");
  CHECK_THAT(unit_value(unit, "Documentation"), Catch::StartsWith("file:" + doc_uri));
  // Otherwise the unit is the one in config/ (the hardening tested by apps/daemon_unit).
  CHECK(unit_value(unit, "Type") == "notify");
  CHECK(unit_value(unit, "ProtectSystem") == "strict");

  // Example configs.
  const fs::path cfg_dir = prefix / ERRSEP_INSTALL_DATADIR / "errsep/config";
  for (const char* f : {"machine-example.toml", "simulator.toml"}) {
    INFO(f);
    CHECK(fs::is_regular_file(cfg_dir / f));
  }
  const io::MachineConfig example = io::load_machine_config(cfg_dir / "machine-example.toml");
  CHECK_FALSE(example.sensors.empty());

  // systemd-analyze verify on the installed unit as it is (ExecStart= must exist for it).
  const fs::path analyze = "/usr/bin/systemd-analyze";
  if (!fs::exists(analyze)) {
    std::cout << "SKIPPED: systemd-analyze not installed; installed unit not verified\n";
    return;
  }
  std::string vout;
  const int vrc =
      test::run_command(analyze.string() + " verify '" + unit_path.string() + "'", &vout);
  INFO(vout);
  CHECK(vrc == 0);
  CHECK(vout.find("errsep.service") == std::string::npos);
}

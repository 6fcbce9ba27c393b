// SIGKILL at random points of many scans (moving, averaging, writing): every result file present
// afterwards parses completely -- whole or absent, never truncated -- and a restarted daemon
// removes the temporary files a killed writer left and does not reuse a scan id on disk.
#include <signal.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <fstream>
#include <random>
#include <set>
#include <thread>

#include "errsep/io/csv.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "errsep/io/results_store.hpp"
#include "support/daemon_rig.hpp"

using namespace errsep;
using namespace std::chrono_literals;
using test::DaemonRig;

TEST_CASE("SIGKILL at random points of many scans leaves only whole result files") {
  DaemonRig rig;
  rig.devsim.start(rig.config, rig.tmp / "devsim.log");
  const unsigned seed = 20261123;
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> delay_ms(0, 2500);
  const int kills = 10;
  for (int k = 0; k < kills; ++k) {
    rig.start_daemon();
    REQUIRE(rig.notify->wait_for("READY=1", 15s));
    REQUIRE(test::mbpoll_write_coil(rig.modbus_port, 0, 1) == 0);
    if (k == kills - 1) {
      // The last life: kill right after a scan completed, so at least one is on disk.
      const auto r = rig.wait_regs(
          [](const std::vector<long>& x) { return x[test::reg_scans_completed] >= 1; }, 20s);
      REQUIRE(r.size() == test::kRegisterCount);
    } else {
      const int d = delay_ms(rng);
      INFO("seed " << seed << ", kill " << k << " after " << d << " ms");
      std::this_thread::sleep_for(std::chrono::milliseconds(d));
    }
    rig.daemon->signal(SIGKILL);
    REQUIRE(rig.daemon->wait(5s));
    rig.daemon.reset();
    // A fresh notify socket per life: messages of the killed daemon are not READY of the next.
    rig.notify = std::make_unique<test::NotifyListener>(rig.tmp / ("notify" + std::to_string(k)));
  }

  // Every store file present parses completely.
  int raws = 0, results = 0, temporaries = 0;
  std::set<std::uint64_t> ids;
  for (const auto& e : std::filesystem::directory_iterator(rig.results)) {
    const std::string name = e.path().filename().string();
    if (name.rfind('.', 0) == 0 && name.find(".tmp.") != std::string::npos) {
      ++temporaries;  // a killed writer's temporary file: not a result, removed at restart
      continue;
    }
    const auto f = io::parse_store_name(e.path());
    INFO(name);
    REQUIRE(f);
    ids.insert(f->scan_id);
    if (f->kind == "raw") {
      const auto scan = io::read_raw_four_sensor_csv(e.path());  // complete, every cell a number
      CHECK(scan.complete);
      REQUIRE(scan.geometry);
      CHECK(scan.positions() == static_cast<std::size_t>(scan.geometry->positions()));
      ++raws;
    } else if (f->kind == "result") {
      const io::CsvTable t = io::read_csv(e.path());
      CHECK(t.meta("straightness_minimum_zone_um"));
      CHECK(t.meta("straightness_least_squares_um"));
      CHECK(t.rows.size() == t.column("S_um").size());
      CHECK(t.rows.size() > 1);
      // A result is written after its raw file, so the raw file is there too.
      CHECK(rig.find_file(f->scan_id, "raw"));
      ++results;
    } else {
      FAIL("unexpected file kind '" << f->kind << "' after SIGKILL (no clean stop happened)");
    }
  }
  WARN(kills << " SIGKILLs (seed " << seed << "): " << raws << " complete raw files, " << results
             << " result files, " << temporaries << " temporaries left by killed writers");
  CHECK(raws >= 1);

  // A restart removes the temporaries and continues the scan ids after those on disk.  One is
  // planted, as a kill inside write_file_atomic leaves it (a kill rarely lands in that window).
  const auto planted = rig.results / ".20261123T000000Z_scan000999.raw.csv.tmp.Ab12Cd";
  { std::ofstream(planted) << "# format: errsep raw four-sensor scan\n# complete: tr"; }
  rig.start_daemon();
  REQUIRE(rig.notify->wait_for("READY=1", 15s));
  for (const auto& e : std::filesystem::directory_iterator(rig.results))
    CHECK(e.path().filename().string().find(".tmp.") == std::string::npos);
  CHECK_FALSE(std::filesystem::exists(planted));
  REQUIRE(test::mbpoll_write_coil(rig.modbus_port, 0, 1) == 0);
  const auto r =
      rig.wait_regs([](const std::vector<long>& x) { return x[test::reg_state] == 2; }, 20s);
  REQUIRE(r.size() == test::kRegisterCount);
  CHECK(ids.count(static_cast<std::uint64_t>(r[test::reg_scan_id])) == 0);
  CHECK(static_cast<std::uint64_t>(r[test::reg_scan_id]) > *ids.rbegin());
}

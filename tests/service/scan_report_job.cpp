// service::write_result_report_logged, errsep-daemon's report after each scan: a report in the
// result folder's report/ and one journal line saying where; a report that fails logs why at
// error priority and leaves every file of the scan's result set as it was; no result folder
// (a scan without separation), no report and no line.
#include "errsep/service/scan_report_job.hpp"

#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <string>

#include "errsep/io/staged_directory.hpp"
#include "errsep/service/four_sensor_pipeline.hpp"
#include "support/raw_scan_cases.hpp"
#include "support/support.hpp"

using namespace errsep;
namespace fs = std::filesystem;

namespace {

/// A result set as the daemon writes it, of a random smooth slideway with noise on each reading.
void write_result_set(const fs::path& dir, std::uint64_t seed) {
  const auto r =
      service::FourSensorPipeline({}).write_result_set(test::simulated_raw(seed), dir, "test");
  REQUIRE(r.separation);
}

/// Every file under `dir` with its contents.
std::map<std::string, std::string> contents_under(const fs::path& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) {
      std::ifstream in(e.path(), std::ios::binary);
      out[fs::relative(e.path(), dir).generic_string()] =
          std::string(std::istreambuf_iterator<char>(in), {});
    }
  return out;
}

io::ScanReportOptions quick_options() {
  io::ScanReportOptions ro = service::result_report_options(io::MachineConfig{}, false);
  ro.plots = false;  // the figures are the report tests'; this one is about where and what fails
  return ro;
}

}  // namespace

TEST_CASE("the daemon's report goes into report/ of the result set and is logged") {
  test::TempDir tmp;
  const fs::path dir = tmp / "scan-1";
  write_result_set(dir, 11);
  std::ostringstream log;
  CHECK(service::write_result_report_logged(dir, quick_options(), log));
  INFO(log.str());
  CHECK(fs::exists(dir / "report" / "evaluation.csv"));
  CHECK(fs::exists(dir / "report" / "report.html"));
  CHECK(io::check_result_set(dir).whole());
  CHECK(log.str().find("<6>scan-1: report: ") != std::string::npos);
  CHECK(log.str().find("<3>") == std::string::npos);
}

TEST_CASE("a report that fails is logged and leaves the scan's results as they were") {
  test::TempDir tmp;
  const fs::path dir = tmp / "scan-2";
  write_result_set(dir, 12);
  fs::remove(dir / "motion.csv");  // the set no longer matches its manifest: the report refuses
  const auto before = contents_under(dir);
  std::ostringstream log;
  CHECK_FALSE(service::write_result_report_logged(dir, quick_options(), log));
  INFO(log.str());
  CHECK(log.str().rfind("<3>scan-2: the report failed: ", 0) == 0);
  CHECK(contents_under(dir) == before);
  CHECK_FALSE(fs::exists(dir / "report"));
}

TEST_CASE("no result folder, no report and no log line") {
  test::TempDir tmp;
  std::ostringstream log;
  CHECK_FALSE(service::write_result_report_logged(tmp / "absent", quick_options(), log));
  CHECK(log.str().empty());
  CHECK_FALSE(fs::exists(tmp / "absent"));
}

// errsep-scan --method displacement on the embedded device simulator (issue 17: the displacement
// scan through the same pipeline as errsep-separate-displacement and errsep-daemon): the result
// folder holds the raw scan, the joint estimate with its uncertainty and '# source:'
// (displacement.csv) and the residuals; it is one whole result set; errsep-scan makes the report
// into report/ by default (none with --no-report); errsep-report reads the folder; and
// errsep-separate-displacement on the raw file gives the same numbers (one use case, once).
#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>

#include "errsep/io/csv.hpp"
#include "errsep/io/staged_directory.hpp"
#include "support/result_files.hpp"
#include "support/support.hpp"

using namespace errsep;
using errsep::test::app_path;
using errsep::test::run_command;
using errsep::test::TempDir;
namespace fs = std::filesystem;

namespace {

// The embedded default config with faster stages.
fs::path write_test_config(const TempDir& dir) {
  const auto path = dir / "machine.toml";
  std::ofstream(path) << test::quick_simulator_config();
  return path;
}

std::string scan_cmd(const fs::path& cfg, const fs::path& out, const std::string& report_flag) {
  return app_path("scan").string() + " --config " + cfg.string() + " --out " + out.string() +
         " --devsim " + app_path("devsim").string() +
         " --method displacement --averages 5 --settle-ms 0 --no-mqtt " + report_flag;
}

}  // namespace

TEST_CASE("scan --method displacement: result folder with u, the report, errsep-report reads it") {
  TempDir dir;
  const auto cfg = write_test_config(dir);
  const fs::path out = dir / "out";
  std::string output;
  const int rc = run_command(scan_cmd(cfg, out, "--no-pdf"), &output);
  INFO(output);
  REQUIRE(rc == 0);
  CHECK_THAT(output, Catch::Contains("displacement scan complete: 50/50 points"));

  // One whole result set: the raw scan, the separation, the residuals, the report.
  for (const char* f : {"raw_displacement.csv", "displacement.csv", "displacement_residuals.csv",
                        "report/evaluation.csv", "report/evaluation.txt", "report/report.html"}) {
    INFO(f);
    CHECK(fs::exists(out / f));
  }
  CHECK(io::check_result_set(out).whole());
  CHECK_THAT(output, Catch::Contains("report: " + (out / "report" / "report.html").string()));

  // The joint estimate with its standard uncertainties, and where it came from.
  const auto t = io::read_csv(out / "displacement.csv");
  for (const char* c : {"x_mm", "r_um", "m_um", "w_um", "u_r_um", "u_m_um", "u_w_um"}) {
    INFO(c);
    CHECK(t.find_column(c));
  }
  CHECK(t.meta("source") == std::optional<std::string>((out / "raw_displacement.csv").string()));
  REQUIRE(t.rows.size() == 25);
  for (double u : t.column("u_w_um"))
    CHECK((std::isfinite(u) && u > 0));

  // The report's evaluation: the table motion error with an expanded uncertainty.
  const auto ev = io::read_csv(out / "report" / "evaluation.csv", {.allow_empty = true});
  CHECK_FALSE(ev.columns.empty());
  const std::string evtxt = test::read_file(out / "report" / "evaluation.txt");
  CHECK_THAT(evtxt, Catch::Contains("table motion error m(x)"));
  // The report states when the displacement scan was measured (its raw file's started_utc).
  const std::string raw_text = test::read_file(out / "raw_displacement.csv");
  const auto at = raw_text.find("# started_utc: ");
  REQUIRE(at != std::string::npos);
  const std::string started = raw_text.substr(at + 15, raw_text.find('\n', at) - at - 15);
  CHECK_THAT(test::read_file(out / "report" / "report.html"), Catch::Contains(started));

  // errsep-report reads the folder (again, into the folder itself).
  std::string rep;
  const int rrc =
      run_command(app_path("report").string() + " " + out.string() + " --no-plots", &rep);
  INFO(rep);
  CHECK(rrc == 0);

  // errsep-separate-displacement on the raw file: the same numbers (the same pipeline).
  std::string sep;
  REQUIRE(run_command(app_path("separate-displacement").string() + " one-axis -i " +
                          (out / "raw_displacement.csv").string() + " -o " +
                          (dir / "again.csv").string(),
                      &sep) == 0);
  const auto again = io::read_csv(dir / "again.csv");
  REQUIRE(again.columns == t.columns);
  for (const char* c : {"w_um", "m_um", "u_w_um"}) {
    const auto a = t.column(c), b = again.column(c);
    REQUIRE(a.size() == b.size());
    for (std::size_t k = 0; k < a.size(); ++k)
      CHECK(a[k] == Approx(b[k]).margin(1e-9));
  }
}

TEST_CASE("scan --method displacement --no-report: the results, no report") {
  TempDir dir;
  const auto cfg = write_test_config(dir);
  const fs::path out = dir / "out";
  std::string output;
  const int rc = run_command(scan_cmd(cfg, out, "--no-report"), &output);
  INFO(output);
  REQUIRE(rc == 0);
  CHECK(fs::exists(out / "displacement.csv"));
  CHECK_FALSE(fs::exists(out / "report"));
  CHECK(io::check_result_set(out).whole());
}

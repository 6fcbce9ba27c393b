// errsep-scan --refine: after the scan and its separation, the refine step runs on the raw file
// and writes its report and refined results to OUT/refine/, the same files errsep-refine writes
// from that raw file (one library call, io::run_refine, behind both).
#include <algorithm>
#include <catch2/catch.hpp>
#include <fstream>
#include <sstream>

#include "errsep/io/csv.hpp"
#include "support/support.hpp"

using namespace errsep;
using test::app_path;
using test::run_command;
using test::TempDir;

namespace {

std::string read_text(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// The text without its "# run_id:" line: two runs write the same results under their own ids.
std::string same_results(const std::filesystem::path& p) {
  std::istringstream in(read_text(p));
  std::string out, line;
  while (std::getline(in, line))
    if (line.rfind("# run_id:", 0) != 0) out += line + "\n";
  return out;
}

void replace_all(std::string& s, const std::string& from, const std::string& to) {
  for (auto pos = s.find(from); pos != std::string::npos; pos = s.find(from, pos + to.size()))
    s.replace(pos, from.size(), to);
}

// The embedded default config made quick, as in scan_end_to_end: N = 40, fast stages.
std::filesystem::path write_test_config(const TempDir& dir) {
  std::string t = read_text(test::source_dir() / "config" / "simulator.toml");
  REQUIRE(t.find("N = 69") != std::string::npos);
  replace_all(t, "N = 69", "N = 40");
  replace_all(t, "speed_mm_s = 200.0", "speed_mm_s = 2000.0");
  replace_all(t, "speed_mm_s = 100.0", "speed_mm_s = 2000.0");
  const auto path = dir / "machine.toml";
  std::ofstream(path) << t;
  return path;
}

std::string scan_cmd(const std::filesystem::path& cfg, const std::filesystem::path& out) {
  return app_path("scan").string() + " --config " + cfg.string() + " --out " + out.string() +
         " --devsim " + app_path("devsim").string() + " --averages 5 --settle-ms 0";
}

}  // namespace

TEST_CASE("scan --refine writes the refine report and refined results, as errsep-refine does") {
  TempDir dir;
  const auto cfg = write_test_config(dir);
  const auto out = dir / "scan";
  std::string output;
  const int rc = run_command(scan_cmd(cfg, out) + " --refine", &output);
  INFO(output);
  REQUIRE(rc == 0);
  CHECK(output.find("refine: model zhao2019-eq1") != std::string::npos);
  for (const char* f : {"refine_report.txt", "refine_steps.csv", "motion.csv", "reference.csv",
                        "residuals.csv", "lcurve.csv", "summary.txt"})
    CHECK(std::filesystem::exists(out / "refine" / f));
  // The scan's own results are still there, unrefined.
  CHECK(std::filesystem::exists(out / "motion.csv"));
  const io::CsvTable motion = io::read_csv(out / "refine" / "motion.csv");
  REQUIRE(motion.meta("model"));
  CHECK(motion.meta("model")->rfind("zhao2019-eq1", 0) == 0);
  CHECK(!io::read_csv(out / "motion.csv").meta("model"));
  // The scan recorded reading times; the refine step used them (t1_s..t4_s in the raw file).
  CHECK(io::read_csv(out / "raw.csv").find_column("t1_s"));

  // errsep-refine on the same raw file: the same step table, the same report.
  std::string output2;
  const auto out2 = dir / "refine";
  REQUIRE(run_command(app_path("refine").string() + " " + (out / "raw.csv").string() + " --out " +
                          out2.string(),
                      &output2) == 0);
  CHECK(same_results(out2 / "refine_steps.csv") ==
        same_results(out / "refine" / "refine_steps.csv"));
  CHECK(read_text(out2 / "refine_report.txt") == read_text(out / "refine" / "refine_report.txt"));
  CHECK(same_results(out2 / "motion.csv") == same_results(out / "refine" / "motion.csv"));
}

TEST_CASE("scan --refine with --no-separate is refused before anything runs") {
  TempDir dir;
  const auto cfg = write_test_config(dir);
  std::string output;
  const int rc = run_command(scan_cmd(cfg, dir / "scan") + " --refine --no-separate", &output);
  INFO(output);
  CHECK(rc != 0);
  CHECK(output.find("excludes") != std::string::npos);
  CHECK(!std::filesystem::exists(dir / "scan"));
}

namespace {

// The quick test config with a [refine] table appended; `line` gets the line of its first key.
std::filesystem::path write_config_with_refine(const TempDir& dir, const std::string& body,
                                               int* line) {
  const auto path = write_test_config(dir);
  std::string t = read_text(path);
  if (!t.empty() && t.back() != '\n') t += '\n';
  *line = static_cast<int>(std::count(t.begin(), t.end(), '\n')) + 2;
  t += "[refine]\n" + body;
  std::ofstream(path) << t;
  return path;
}

}  // namespace

TEST_CASE("[refine] enabled = true in the machine config runs the refine step like --refine") {
  TempDir dir;
  int line = 0;
  const auto cfg = write_config_with_refine(dir, "enabled = true\nalpha = 0.01\n", &line);
  const auto out = dir / "scan";
  std::string output;
  const int rc = run_command(scan_cmd(cfg, out), &output);
  INFO(output);
  REQUIRE(rc == 0);
  CHECK(output.find("refine: model zhao2019-eq1") != std::string::npos);
  for (const char* f : {"refine_report.txt", "refine_steps.csv", "motion.csv"})
    CHECK(std::filesystem::exists(out / "refine" / f));
  // The same step table errsep-refine writes from the raw file (alpha 0.01 is its default).
  const auto out2 = dir / "refine";
  std::string output2;
  REQUIRE(run_command(app_path("refine").string() + " " + (out / "raw.csv").string() + " --out " +
                          out2.string(),
                      &output2) == 0);
  CHECK(same_results(out2 / "refine_steps.csv") ==
        same_results(out / "refine" / "refine_steps.csv"));
}

TEST_CASE("[refine] enabled = false (the default) runs no refine step") {
  TempDir dir;
  int line = 0;
  const auto cfg = write_config_with_refine(dir, "enabled = false\n", &line);
  const auto out = dir / "scan";
  std::string output;
  const int rc = run_command(scan_cmd(cfg, out), &output);
  INFO(output);
  REQUIRE(rc == 0);
  CHECK(std::filesystem::exists(out / "motion.csv"));
  CHECK(!std::filesystem::exists(out / "refine"));
}

TEST_CASE("a bad [refine] value is a file:line error and nothing runs") {
  struct Bad {
    const char* body;
    const char* key;
    const char* problem;
  };
  for (const Bad& b : {Bad{"enabled = \"yes\"\n", "refine.enabled", "expected true or false"},
                       Bad{"enabled = true\nalpha = 1.5\n", "refine.alpha", "must be in (0, 1)"},
                       Bad{"enable = true\n", "refine.enable", "unknown key"}}) {
    TempDir dir;
    int line = 0;
    const auto cfg = write_config_with_refine(dir, b.body, &line);
    if (std::string(b.key) == "refine.alpha") ++line;  // alpha is the second key
    std::string output;
    const int rc = run_command(scan_cmd(cfg, dir / "scan"), &output);
    INFO(b.body << output);
    CHECK(rc != 0);
    const std::string where = cfg.string() + ":" + std::to_string(line) + ":";
    CHECK(output.find(where) != std::string::npos);
    CHECK(output.find(b.key) != std::string::npos);
    CHECK(output.find(b.problem) != std::string::npos);
    CHECK(!std::filesystem::exists(dir / "scan"));
  }
}

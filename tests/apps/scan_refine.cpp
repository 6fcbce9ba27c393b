// errsep-scan --refine: after the scan and its separation, the refine step runs on the raw file
// and writes its report and refined results to OUT/refine/, the same files errsep-refine writes
// from that raw file (one library call, service::run_refine, behind both).
#include <algorithm>
#include <catch2/catch.hpp>
#include <cstdio>
#include <cstdlib>
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

namespace {

// The quick test config with an undeclared gain: configuration 3 reads 5 % high (the device
// simulator's [simulator] gain), which the separation's model does not know.
std::filesystem::path write_config_with_gain(const TempDir& dir) {
  const auto path = write_test_config(dir);
  std::string t = read_text(path);
  REQUIRE(t.find("[simulator]\n") != std::string::npos);
  replace_all(t, "[simulator]\n", "[simulator]\ngain = [1.0, 1.0, 1.05, 1.0]\n");
  std::ofstream(path) << t;
  return path;
}

std::string fmt4(double v) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

}  // namespace

TEST_CASE(
    "scan --refine on an undeclared gain: the report's refine table shows the step, before "
    "and after") {
  TempDir dir;
  const auto cfg = write_config_with_gain(dir);
  const auto out = dir / "scan";
  std::string output;
  const int rc = run_command(scan_cmd(cfg, out) + " --refine", &output);
  INFO(output);
  REQUIRE(rc == 0);
  // The report is made by default, into OUT/report/, and the scan says where it is.
  const auto report = out / "report" / "report.html";
  REQUIRE(std::filesystem::exists(report));
  CHECK(output.find("report: " + report.string()) != std::string::npos);
  for (const char* f :
       {"evaluation.csv", "evaluation.txt", "plots/straightness.png", "compensation/accuracy.csv"})
    CHECK(std::filesystem::exists(out / "report" / f));
  CHECK(std::filesystem::exists(out / "motion.csv"));  // the scan's own results stay where they are

  // The refine step found the gain, and the fit got better by it.
  io::CsvReadOptions nan_ok;
  nan_ok.allow_non_finite = true;
  const io::CsvTable steps = io::read_csv(out / "refine" / "refine_steps.csv", nan_ok);
  REQUIRE(steps.meta("step1_effect"));
  CHECK(*steps.meta("step1_effect") == "gain");
  const auto col = [&](const char* name) { return *steps.find_column(name); };
  const std::vector<double>* step1 = nullptr;
  for (const auto& r : steps.rows)
    if (r[col("step")] == 1.0 && !step1) step1 = &r;
  REQUIRE(step1);
  const double before = (*step1)[col("rms_before_um")], after = (*step1)[col("rms_after_um")];
  std::printf("gain step: residual RMS %.4g -> %.4g um\n", before, after);
  CHECK(after < before);

  // The report's refine table: the step, its effect and the residual before -> after, as read
  // from the step table (not a free-form dump of its columns).
  const std::string html = read_text(report);
  const auto table = html.find("<table id=\"refine\">");
  REQUIRE(table != std::string::npos);
  const std::string t = html.substr(table, html.find("</table>", table) - table);
  CHECK(t.find("<td>gain</td>") != std::string::npos);
  CHECK(t.find("residual RMS before \xE2\x86\x92 after") != std::string::npos);
  CHECK(t.find(fmt4(before) + " \xE2\x86\x92 " + fmt4(after)) != std::string::npos);
  CHECK(t.find("g3 = ") != std::string::npos);  // the fitted gain of configuration 3, with its u
  CHECK(t.find("nan") == std::string::npos);

  // errsep-report reads the refine result on its own too (OUT/refine, as errsep-refine writes
  // it): the refined S evaluated, the same step table.
  std::string rep;
  REQUIRE(run_command(app_path("report").string() + " " + (out / "refine").string(), &rep) == 0);
  INFO(rep);
  const std::string rhtml = read_text(out / "refine" / "report.html");
  CHECK(rhtml.find("<table id=\"refine\">") != std::string::npos);
  CHECK(rhtml.find("<td>gain</td>") != std::string::npos);
  CHECK(rhtml.find("<table id=\"evaluation\">") != std::string::npos);
}

TEST_CASE("scan --no-report makes no report") {
  TempDir dir;
  const auto cfg = write_test_config(dir);
  const auto out = dir / "scan";
  std::string output;
  const int rc = run_command(scan_cmd(cfg, out) + " --no-report", &output);
  INFO(output);
  REQUIRE(rc == 0);
  CHECK(std::filesystem::exists(out / "motion.csv"));
  CHECK(!std::filesystem::exists(out / "report"));
}

namespace {

// Fraction of pixels darker than near-white in a binary PGM (pdftoppm -gray).
double ink_fraction(const std::filesystem::path& pgm, int* width, int* height) {
  std::ifstream in(pgm, std::ios::binary);
  std::string magic;
  int maxval = 0;
  in >> magic >> *width >> *height >> maxval;
  in.get();
  REQUIRE(magic == "P5");
  REQUIRE(maxval == 255);
  std::string px(static_cast<std::size_t>(*width) * static_cast<std::size_t>(*height), '\0');
  in.read(px.data(), static_cast<std::streamsize>(px.size()));
  REQUIRE(in.gcount() == static_cast<std::streamsize>(px.size()));
  std::size_t ink = 0;
  for (char c : px)
    ink += static_cast<unsigned char>(c) < 200;
  return static_cast<double>(ink) / static_cast<double>(px.size());
}

}  // namespace

// Registered separately (tests/apps/scan_refine.cmake) with SKIP_RETURN_CODE 77.
TEST_CASE("the scan's report.pdf renders to a page that is not blank", "[chromium]") {
  for (const char* tool : {"/usr/bin/chromium", "/usr/bin/pdftoppm"})
    if (!std::filesystem::exists(tool)) {
      std::printf(
          "SKIPPED: %s is not installed (apt-get install chromium poppler-utils); the "
          "PDF was not checked.\n",
          tool);
      std::fflush(stdout);
      std::exit(77);
    }
  TempDir dir;
  const auto cfg = write_test_config(dir);
  {
    std::ofstream(cfg, std::ios::app)
        << "\n[report]\nmachine = \"test bench 1\"\noperator = \"A. Tester\"\n"
           "instrument = \"simulated four-sensor rig\"\ntemperature_c = 20.3\n"
           "straightness_tolerance_um = 50.0\n";
  }
  const auto out = dir / "scan";
  std::string output;
  const int rc = run_command(scan_cmd(cfg, out) + " --refine", &output);
  INFO(output);
  REQUIRE(rc == 0);
  const auto pdf = out / "report" / "report.pdf";
  REQUIRE(std::filesystem::exists(pdf));
  CHECK(output.find("report (PDF): " + pdf.string()) != std::string::npos);
  CHECK(read_text(pdf).rfind("%PDF-", 0) == 0);
  // The particulars and the verdict are in the report.
  const std::string html = read_text(out / "report" / "report.html");
  for (const char* s :
       {"<table id=\"measurement\">", "test bench 1", "A. Tester", "simulated four-sensor rig",
        "20.3", "ISO 230-1", "<div id=\"verdict\"", "Appendix: diagnostics"})
    CHECK(html.find(s) != std::string::npos);

  // Page 1 as the customer sees it: rendered by poppler, not blank.
  const auto shot = test::binary_dir() / "scan_report_pdf_page1";
  std::filesystem::remove(shot.string() + ".png");
  REQUIRE(run_command("pdftoppm -f 1 -l 1 -r 60 -singlefile -png '" + pdf.string() + "' '" +
                      shot.string() + "'") == 0);
  REQUIRE(run_command("pdftoppm -f 1 -l 1 -r 60 -singlefile -gray '" + pdf.string() + "' '" +
                      (dir / "page1").string() + "'") == 0);
  int w = 0, h = 0;
  const double ink = ink_fraction(dir / "page1.pgm", &w, &h);
  std::printf("report.pdf page 1: %d x %d px at 60 dpi, %.2f %% of the pixels inked; PNG: %s.png\n",
              w, h, 100 * ink, shot.string().c_str());
  CHECK(w > 400);  // A4 or Letter at 60 dpi: ~500 x 700 px
  CHECK(h > 600);
  CHECK(ink > 0.01);  // text, tables and lines; a blank page has none
  CHECK(ink < 0.6);   // and not a black page either
  std::string info;
  REQUIRE(run_command("pdfinfo '" + pdf.string() + "'", &info) == 0);
  std::printf("%s\n", info.c_str());
}

TEST_CASE("a report that fails keeps the scan's results and exits non-zero with the reason") {
  TempDir dir;
  const auto cfg = write_test_config(dir);
  // A table step that cannot divide the measured range: the compensation export, part of the
  // report, fails after the scan's results are in place.
  std::string t = read_text(cfg);
  REQUIRE(t.find("max_points = 200") != std::string::npos);
  replace_all(t, "max_points = 200", "max_points = 200\nstep_mm = 7.3");
  std::ofstream(cfg) << t;
  const auto out = dir / "scan";
  std::string output;
  const int rc = run_command(scan_cmd(cfg, out), &output);
  INFO(output);
  CHECK(rc == 4);
  CHECK(output.find("errsep-scan: the report failed: ") != std::string::npos);
  CHECK(output.find("does not divide") != std::string::npos);
  CHECK(output.find("the scan's results are kept in " + out.string()) != std::string::npos);
  for (const char* f : {"raw.csv", "motion.csv", "reference.csv", "summary.txt"})
    CHECK(std::filesystem::exists(out / f));
  CHECK(!std::filesystem::exists(out / "report"));
  // The set is whole: errsep-report reads it (and, with a step that divides, would report it).
  CHECK(output.find("results: " + out.string()) != std::string::npos);
}

TEST_CASE(
    "the separation table of the machine config is honoured by errsep-scan and errsep-refine, "
    "--gauge over it") {
  TempDir dir;
  const auto cfg = write_test_config(dir);
  std::string t = read_text(cfg);
  const std::string from = "gauge = \"reference\"";
  REQUIRE(t.find(from) != std::string::npos);
  t.replace(t.find(from), from.size(), "gauge = \"sensor_stage\"");
  std::ofstream(cfg) << t;
  auto gauge_of = [](const std::filesystem::path& result) {
    return io::read_csv(result / "reference.csv").meta("gauge").value_or("?");
  };
  std::string output;
  REQUIRE(run_command(scan_cmd(cfg, dir / "a") + " --no-report", &output) == 0);
  CHECK(gauge_of(dir / "a") == "sensor_stage");
  REQUIRE(run_command(scan_cmd(cfg, dir / "b") + " --no-report --gauge reference", &output) == 0);
  CHECK(gauge_of(dir / "b") == "reference");
  // errsep-refine --config: the same table.
  REQUIRE(run_command(app_path("refine").string() + " " + (dir / "a" / "raw.csv").string() +
                          " --config " + cfg.string() + " --out " + (dir / "r").string(),
                      &output) == 0);
  INFO(output);
  CHECK(gauge_of(dir / "r") == "sensor_stage");
}

// errsep-separate run as a user would: on a simulated raw scan (results checked against the truth
// within their stated uncertainty) and on malformed ones (one line naming the file, the line where
// there is one, and the problem; exit status 1; no result written and an earlier result left
// alone).
#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <sstream>

#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "support/support.hpp"

using namespace errsep;
using test::TempDir;

namespace {

int run(const std::string& args, std::string* out) {
  return test::run_command(test::app_path("separate").string() + " " + args, out);
}

core::FourSensorSimData simulate(std::uint64_t seed = 7) {
  const core::FourSensorConfig cfg;
  core::FourSensorSimOptions so;
  so.sigma_um = 0.1;
  so.seed = seed;
  return core::simulate_four_sensor(cfg, core::zhao2019_example1(cfg), so);
}

io::RawFourSensorScan raw_of(const core::FourSensorSimData& sim, bool with_geometry = true) {
  io::RawFourSensorScan raw;
  raw.complete = true;
  if (with_geometry) raw.geometry = core::FourSensorConfig{};
  raw.x_mm.assign(sim.x_mm.data(), sim.x_mm.data() + sim.x_mm.size());
  for (int j = 0; j < 4; ++j)
    for (Eigen::Index n = 0; n < sim.m_um.rows(); ++n)
      raw.m_um[static_cast<size_t>(j)].push_back(sim.m_um(n, j));
  return raw;
}

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// Replaces the first line of `file` that starts with `prefix` by `line`; returns its 1-based
/// line number.
std::size_t replace_line(const std::filesystem::path& file, const std::string& prefix,
                         const std::string& line) {
  std::istringstream in(slurp(file));
  std::ostringstream out;
  std::string l;
  std::size_t n = 0, hit = 0;
  while (std::getline(in, l)) {
    ++n;
    if (!hit && l.rfind(prefix, 0) == 0) {
      out << line << "\n";
      hit = n;
    } else {
      out << l << "\n";
    }
  }
  std::ofstream(file) << out.str();
  return hit;
}

// The error is one line: "errsep-separate: <file>:<line>: <problem>".
void check_error(const std::string& out, const std::string& where, const std::string& problem) {
  INFO(out);
  CHECK(std::count(out.begin(), out.end(), '\n') == 1);
  CHECK_THAT(out, Catch::StartsWith("errsep-separate: " + where));
  CHECK_THAT(out, Catch::Contains(problem));
}

}  // namespace

TEST_CASE("a simulated raw scan is separated: S within its stated uncertainty of the truth") {
  TempDir dir;
  const auto sim = simulate();
  io::write_raw_four_sensor_csv(dir / "raw.csv", raw_of(sim));
  std::string out;
  REQUIRE(run((dir / "raw.csv").string() + " --out " + (dir / "res").string(), &out) == 0);
  CHECK_THAT(out, Catch::Contains("results written"));
  for (const char* f :
       {"motion.csv", "reference.csv", "lcurve.csv", "residuals.csv", "summary.txt"})
    CHECK(std::filesystem::exists(dir / "res" / f));
  const auto m = io::read_csv(dir / "res" / "motion.csv");
  const auto S = m.column("S_um"), u = m.column("u_S_um");
  REQUIRE(S.size() == static_cast<std::size_t>(sim.S_um.size()));
  double worst = 0;  // largest |error| in units of the stated uncertainty
  for (std::size_t n = 0; n < S.size(); ++n)
    worst = std::max(worst, std::abs(S[n] - sim.S_um(static_cast<Eigen::Index>(n))) / u[n]);
  INFO("largest |S - S_true| / u_S = " << worst);
  CHECK(worst < 4.0);  // 62 points: a 4u excursion has probability ~0.4 %
  CHECK(worst > 0.0);
  // The header says units, the estimator, the prior, the rule and what it did.
  CHECK(m.meta("units").has_value());
  CHECK(m.meta("estimator") == std::optional<std::string>("posterior"));
  CHECK(m.meta("prior") == std::optional<std::string>("second_difference"));
  CHECK(m.meta("lambda_rule") == std::optional<std::string>("reml"));
  CHECK(m.meta("straightness_minimum_zone_U_um").has_value());
  const auto lc = io::read_csv(dir / "res" / "lcurve.csv");
  CHECK(lc.meta("lambda_fallback").value() == "none");
  CHECK(lc.find_column("reml_criterion").has_value());
  CHECK_THAT(slurp(dir / "res" / "summary.txt"), Catch::Contains("no bow"));
}

TEST_CASE("malformed raw scans: file, line and problem, exit 1, nothing written") {
  TempDir dir;
  const auto sim = simulate();
  const auto raw_file = dir / "raw.csv";
  const auto res_dir = dir / "res";
  std::string out;
  auto fresh = [&](bool geometry = true) {
    io::write_raw_four_sensor_csv(raw_file, raw_of(sim, geometry));
  };
  auto separate = [&](const std::string& extra = "") {
    return run(raw_file.string() + " --out " + res_dir.string() + " " + extra + " 2>&1", &out);
  };

  SECTION("a missing column") {
    io::RawFourSensorScan raw = raw_of(sim, false);
    io::CsvTable t;
    t.add_column("x_mm", raw.x_mm);
    t.add_column("m1_um", raw.m_um[0]);
    t.add_column("m2_um", raw.m_um[1]);
    t.add_column("m4_um", raw.m_um[3]);
    t.set_meta("complete", "true");
    io::write_csv(raw_file, t);
    CHECK(separate() == 1);
    check_error(out, raw_file.string() + ":", "m3_um");
  }
  SECTION("nan in a complete scan names its line") {
    fresh();
    const std::size_t line = replace_line(raw_file, "50,", "50,nan,1,2,3");
    REQUIRE(line > 0);
    CHECK(separate() == 1);
    check_error(out, raw_file.string() + ":" + std::to_string(line) + ":", "");
  }
  SECTION("too few rows for the spacing") {
    io::RawFourSensorScan raw = raw_of(sim, false);
    for (auto& c : raw.m_um)
      c.resize(5);
    raw.x_mm.resize(5);
    io::write_raw_four_sensor_csv(raw_file, raw);
    CHECK(separate("--dx-mm 5 --s2 1 --s3 1 --s4 5") == 1);
    check_error(out, raw_file.string(), "N = 12");
  }
  SECTION("no geometry metadata and no spacings: refused, not assumed") {
    fresh(false);
    CHECK(separate() == 1);
    check_error(out, raw_file.string() + ":", "no sensor spacings");
    CHECK_THAT(out, Catch::Contains("--s2, --s3, --s4"));
    CHECK(separate("--s2 1 --s3 1") == 1);
    check_error(out, raw_file.string() + ":", "--s4 not given");
  }
  SECTION("spacings with a common factor (A rank-deficient beyond the known null space)") {
    fresh(false);
    CHECK(separate("--dx-mm 5 --s2 2 --s3 2 --s4 4") == 1);
    check_error(out, raw_file.string(), "share the factor 2");
  }
  SECTION("a row off the dx grid names its line") {
    fresh();
    const std::size_t line = replace_line(raw_file, "50,", "51,0,0,0,0");
    REQUIRE(line > 0);
    CHECK(separate() == 1);
    check_error(out, raw_file.string() + ":" + std::to_string(line) + ":", "dx = 5");
  }
  SECTION("an incomplete (aborted) scan is refused") {
    io::RawFourSensorScan raw = raw_of(sim);
    raw.complete = false;
    io::write_raw_four_sensor_csv(raw_file, raw);
    CHECK(separate() == 1);
    check_error(out, raw_file.string(), "incomplete");
  }
  // Nothing was written for any of them, not even an empty result directory or a staging one.
  CHECK_FALSE(std::filesystem::exists(res_dir));
  for (const auto& e : std::filesystem::directory_iterator(dir.path()))
    CHECK(e.path().filename().string().find("partial") == std::string::npos);
}

TEST_CASE("a raw scan without geometry metadata is separated with the spacings given") {
  TempDir dir;
  io::write_raw_four_sensor_csv(dir / "raw.csv", raw_of(simulate(), false));
  std::string out;
  CHECK(run((dir / "raw.csv").string() + " --out " + (dir / "res").string() +
                " --s2 1 --s3 1 --s4 5 2>&1",
            &out) == 0);
  INFO(out);
  CHECK(std::filesystem::exists(dir / "res" / "motion.csv"));
}

TEST_CASE("an error leaves an earlier result alone") {
  TempDir dir;
  io::write_raw_four_sensor_csv(dir / "raw.csv", raw_of(simulate()));
  std::string out;
  REQUIRE(run((dir / "raw.csv").string() + " --out " + (dir / "res").string(), &out) == 0);
  const std::string before = slurp(dir / "res" / "motion.csv");
  replace_line(dir / "raw.csv", "50,", "50,nan,1,2,3");
  CHECK(run((dir / "raw.csv").string() + " --out " + (dir / "res").string(), &out) == 1);
  CHECK(slurp(dir / "res" / "motion.csv") == before);
}

TEST_CASE(
    "the separation table of a machine config sets the separation, the command line over it") {
  TempDir dir;
  io::write_raw_four_sensor_csv(dir / "raw.csv", raw_of(simulate()));
  std::string cfg_text;
  {
    std::ifstream in(test::source_dir() / "config" / "simulator.toml");
    std::stringstream ss;
    ss << in.rdbuf();
    cfg_text = ss.str();
  }
  // The shipped config has a [separation] table: give it another rule.
  const std::string from = "threads = 1                     # threads of the lambda search";
  REQUIRE(cfg_text.find(from) != std::string::npos);
  cfg_text.replace(cfg_text.find(from), from.size(),
                   "lambda_rule = \"gcv\"\nthreads = 2 # threads of the lambda search");
  const auto cfg = dir / "machine.toml";
  std::ofstream(cfg) << cfg_text;
  std::string out;
  REQUIRE(run((dir / "raw.csv").string() + " --config " + cfg.string() + " --out " +
                  (dir / "a").string(),
              &out) == 0);
  INFO(out);
  CHECK(io::read_csv(dir / "a" / "motion.csv").meta("lambda_rule") == "gcv");
  // --rule over [separation].
  REQUIRE(run((dir / "raw.csv").string() + " --config " + cfg.string() + " --rule reml --out " +
                  (dir / "b").string(),
              &out) == 0);
  CHECK(io::read_csv(dir / "b" / "motion.csv").meta("lambda_rule") == "reml");
  // A bad value: file:line: key: what is wrong, nothing written.
  cfg_text.replace(cfg_text.find("lambda_rule = \"gcv\""), 19, "lambda_rule = \"best\"");
  std::ofstream(cfg) << cfg_text;
  CHECK(run((dir / "raw.csv").string() + " --config " + cfg.string() + " --out " +
                (dir / "c").string(),
            &out) == 1);
  CHECK(out.find(cfg.string() + ":") != std::string::npos);
  CHECK(out.find("separation.lambda_rule: 'best' is not one of \"reml\"") != std::string::npos);
  CHECK(!std::filesystem::exists(dir / "c"));
}

// service::FourSensorPipeline, the one four-sensor pipeline of errsep-scan, errsep-separate and
// errsep-daemon: a result set written whole (the files errsep-scan writes, a manifest that checks
// them), the separation in its files as the pipeline returned it, a failed separation leaving the
// raw scan alone, and the settings taken from the machine config.
#include "errsep/service/four_sensor_pipeline.hpp"

#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <limits>
#include <set>
#include <string>

#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/staged_directory.hpp"
#include "support/raw_scan_cases.hpp"
#include "support/support.hpp"

using namespace errsep;
namespace fs = std::filesystem;

namespace {

std::set<std::string> files_in(const fs::path& dir) {
  std::set<std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) out.insert(fs::relative(e.path(), dir).generic_string());
  return out;
}

}  // namespace

TEST_CASE("write_result_set: errsep-scan's files as one whole set, the separation in them") {
  test::TempDir tmp;
  const service::FourSensorPipeline pipeline({});
  const fs::path out = tmp / "scan";
  for (std::uint64_t seed : {3u, 4u}) {  // the second replaces the first whole
    const auto raw = test::simulated_raw(seed);
    const auto r = pipeline.write_result_set(raw, out, "test");
    INFO("seed " << seed << ": " << r.error);
    REQUIRE(r.error.empty());
    REQUIRE(r.separation);
    CHECK(files_in(out) == std::set<std::string>{"errsep-manifest.txt", "raw.csv", "motion.csv",
                                                 "reference.csv", "lcurve.csv", "residuals.csv",
                                                 "summary.txt"});
    CHECK(r.files.front() == "raw.csv");
    const auto check = io::check_result_set(out);
    CHECK(check.whole());
    CHECK(check.kind == "scan");
    // The raw file is the scan's, with the set's run id; motion.csv holds the returned S.
    const auto back = io::read_raw_four_sensor_csv(out / "raw.csv");
    CHECK(back.meta("scan_id") == std::optional<std::string>(std::to_string(seed)));
    CHECK(back.meta("run_id") == std::optional<std::string>(check.run_id));
    const auto S = io::read_csv(out / "motion.csv").column("S_um");
    REQUIRE(S.size() == static_cast<std::size_t>(r.separation->S_um.size()));
    for (std::size_t n = 0; n < S.size(); ++n)
      CHECK(S[n] == Approx(r.separation->S_um(static_cast<Eigen::Index>(n))).margin(1e-6));
  }
}

TEST_CASE("write_result_set: a separation that fails keeps the raw scan alone and says why") {
  test::TempDir tmp;
  auto raw = test::simulated_raw(5);
  raw.m_um[2][7] = std::numeric_limits<double>::quiet_NaN();  // not separable
  const auto r = service::FourSensorPipeline({}).write_result_set(raw, tmp / "scan", "test");
  CHECK_FALSE(r.separation);
  CHECK_THAT(r.error, Catch::Contains("non-finite"));
  CHECK(files_in(tmp / "scan") == std::set<std::string>{"errsep-manifest.txt", "raw.csv"});
  CHECK(io::check_result_set(tmp / "scan").whole());
}

TEST_CASE("pipeline settings from the machine config, and bad settings refused") {
  io::MachineConfig cfg;
  cfg.refine.enabled = true;
  cfg.refine.alpha = 0.05;
  const auto o = service::pipeline_options(cfg, "sensor_stage");
  CHECK(o.refine);
  CHECK(o.refine_alpha == 0.05);
  CHECK(o.separation.gauge == core::CurvatureGauge::sensor_stage_without_curvature);
  CHECK_THROWS_WITH(service::pipeline_options(cfg, "bow"), Catch::Contains("'bow'"));
  service::FourSensorPipelineOptions bad;
  bad.refine_alpha = 1.5;
  CHECK_THROWS_WITH(service::FourSensorPipeline(bad), Catch::Contains("refine_alpha"));
}

// service::FourSensorPipeline, the one four-sensor pipeline of errsep-scan, errsep-separate and
// errsep-daemon: a result set written whole (the files errsep-scan writes, a manifest that checks
// them), the separation in its files as the pipeline returned it, a failed separation leaving the
// raw scan alone, and the settings taken from the machine config; with refine on and a recorded
// scan sequence, the sequence refined once and refine/ holding the same fit as the scan's files.
#include "errsep/service/four_sensor_pipeline.hpp"

#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <set>
#include <string>

#include "errsep/core/four_sensor_sequence_simulation.hpp"
#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/refine_report.hpp"
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

// A raw scan of a random smooth slideway (test::simulated_raw's) measured with the reversed plan,
// every configuration's sensor drifting, noise 0.1 um on each reading.
io::RawFourSensorScan reversed_raw(std::uint64_t seed) {
  io::RawFourSensorScan raw = test::simulated_raw(seed);
  const core::FourSensorConfig& cfg = *raw.geometry;
  const auto seq = core::ScanSequence::make(core::ScanSequenceKind::reversed, cfg);
  core::SequenceSimOptions so;
  so.sigma_um = 0.1;
  so.seed = seed;
  so.effects.drift_um_per_s = {0.02, -0.015, 0.025, 0.01};
  const auto sim =
      core::simulate_four_sensor_sequence(cfg, core::random_smooth_truth(cfg, seed), seq, so);
  io::set_sequence(raw, seq, sim.m_um, sim.t_s);
  return raw;
}

std::string meta(const io::CsvTable& t, const std::string& key) {
  return t.meta(key).value_or("(absent)");
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

// Review of issue 16: the pipeline refined a recorded sequence for its own files, then the refine
// step refined it again for refine/ and wrote there the weaker single-scan refine of m1..m4.  Now
// one refine per job, and refine/ holds the fit the scan's files hold.
TEST_CASE("a scan sequence with refine on: refined once, refine/ holds the scan's sequence fit") {
  test::TempDir tmp;
  service::FourSensorPipelineOptions o;
  o.refine = true;
  const service::FourSensorPipeline pipeline(o);
  for (std::uint64_t seed : {21u, 22u}) {
    const fs::path out = tmp / ("scan" + std::to_string(seed));
    const auto raw = reversed_raw(seed);
    const auto t0 = std::chrono::steady_clock::now();
    const auto r = pipeline.write_result_set(raw, out, "test");
    const auto t1 = std::chrono::steady_clock::now();
    {
      // What a second refine of the sequence cost (the time saved per job), for the record.
      const auto [seq, m] = io::scan_sequence_of(raw);
      core::SequenceRefineOptions so;
      so.alpha = o.refine_alpha;
      (void)core::refine_four_sensor_sequence(*raw.geometry, seq, m, so);
    }
    const auto t2 = std::chrono::steady_clock::now();
    std::printf(
        "seed %d: the scan with refine %.3f s; one sequence refine %.3f s (no longer made "
        "twice)\n",
        static_cast<int>(seed), std::chrono::duration<double>(t1 - t0).count(),
        std::chrono::duration<double>(t2 - t1).count());
    INFO("seed " << seed << ": " << r.error);
    REQUIRE(r.error.empty());
    REQUIRE(r.sequence_refine);
    REQUIRE(r.refine);
    CHECK(r.sequence_refines == 1);
    const auto files = files_in(out);
    for (const char* f : {"refine/sequence_refine.csv", "refine/refine_steps.csv",
                          "refine/refine_report.txt", "refine/motion.csv", "refine/summary.txt"})
      CHECK(files.count(f) == 1);
    CHECK(io::check_result_set(out).whole());
    const auto top = io::read_csv(out / "motion.csv");
    const auto ref = io::read_csv(out / "refine" / "motion.csv");
    CHECK(meta(ref, "estimator") == "scan_sequence_fit");
    CHECK(meta(ref, "scan_plan") == "reversed");
    CHECK(meta(ref, "separation") == meta(top, "separation"));
    CHECK(meta(ref, "uncertainty_model") == meta(top, "uncertainty_model"));
    CHECK(meta(ref, "straightness_minimum_zone_U_um") ==
          meta(top, "straightness_minimum_zone_U_um"));
    // The same numbers, written by the same writer.
    for (const char* c : {"S_um", "u_S_um", "u_gamma_urad"})
      CHECK(ref.column(c, "refine/motion.csv") == top.column(c, "motion.csv"));
    // sequence_refine.csv is of that refine: its S after is motion.csv's S.
    const auto sq = io::read_csv(out / "refine" / "sequence_refine.csv");
    const auto S_after = sq.column("S_after_um", "sequence_refine.csv");
    const auto S = top.column("S_um", "motion.csv");
    REQUIRE(S_after.size() == S.size());
    for (std::size_t n = 0; n < S.size(); ++n)
      CHECK(S_after[n] == Approx(S[n]).margin(1e-6));
    CHECK_THAT(test::read_file(out / "refine" / "refine_report.txt"),
               Catch::Contains("single-scan refine of each configuration's first traverse"));
    // ... and the step table says so (errsep-report words its warnings by it).
    const fs::path steps = out / "refine" / "refine_steps.csv";
    CHECK(io::refine_role_of(io::read_csv(steps, {.allow_non_finite = true}), steps) ==
          io::RefineRole::comparison);
  }
  // Without a recorded sequence nothing is refined as a sequence and refine/ is the single refine.
  const auto r = pipeline.write_result_set(test::simulated_raw(23), tmp / "single", "test");
  REQUIRE(r.error.empty());
  CHECK(r.sequence_refines == 0);
  CHECK_FALSE(r.sequence_refine);
  CHECK(meta(io::read_csv(tmp / "single" / "refine" / "motion.csv"), "estimator") !=
        "scan_sequence_fit");
}

// service::run_refine's result set (errsep-refine): a refined u_S that the data do not bound
// (core::RefineResult::unbounded: the term is held at the readings' bound, a finite number that is
// not a measured uncertainty) is said so in every file a user takes the figures from: motion.csv's
// metadata, summary.txt and refine_steps.csv (which errsep-report turns into a warning).
#include "errsep/service/refine_run.hpp"

#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "errsep/core/four_sensor_sequence_simulation.hpp"
#include "errsep/core/undeclared_effect_simulation.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/four_sensor_inputs.hpp"
#include "errsep/service/sequence_result.hpp"
#include "support/support.hpp"

using namespace errsep;
namespace fs = std::filesystem;

namespace {

io::FourSensorInputs inputs_of(const core::UndeclaredCase& k) {
  io::FourSensorInputs in;
  in.cfg = k.cfg;
  in.x_mm =
      Eigen::VectorXd::LinSpaced(k.cfg.positions(), 0.0, k.cfg.dx_mm * (k.cfg.positions() - 1));
  in.m_um = k.m_um;
  in.t_s = k.t_s;
  return in;
}

std::string read_text(const fs::path& file) {
  std::ifstream f(file);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

}  // namespace

// The run that showed the rule (tests/core/refine_u_bounded.cpp: a 3x bump at sigma 0.3, seed 27),
// and the same scan without the bump.
TEST_CASE("refine result: a u_S the data do not bound is said so in the files, not otherwise") {
  core::UndeclaredCaseOptions co;
  co.sigma_um = 0.3;
  co.seed = 27;
  co.size = 3.0;
  test::TempDir tmp;
  for (const auto effect : {core::UndeclaredEffect::bump, core::UndeclaredEffect::none}) {
    const bool bump = effect == core::UndeclaredEffect::bump;
    INFO((bump ? "bump" : "clean"));
    const fs::path out = tmp / (bump ? "bump" : "clean");
    const service::RefineRunResult r =
        service::run_refine(inputs_of(core::simulate_undeclared(effect, co)), out, {});
    REQUIRE(r.result.unbounded.empty() != bump);
    const io::CsvTable motion = io::read_csv(out / "motion.csv");
    const io::CsvTable steps = io::read_csv(out / "refine_steps.csv", {.allow_non_finite = true});
    const std::string summary = read_text(out / "summary.txt");
    // A single scan: the step table's findings concern the result (errsep-report's wording).
    CHECK(steps.meta("refine_role") == std::optional<std::string>("result"));
    if (bump) {
      CHECK(motion.meta("u_S_bounded_by_data") == std::optional<std::string>("false"));
      CHECK(steps.meta("u_S_unbounded0") == std::optional<std::string>(r.result.unbounded[0]));
      CHECK(summary.find(r.result.unbounded[0]) != std::string::npos);
    } else {
      CHECK_FALSE(motion.meta("u_S_bounded_by_data"));
      CHECK_FALSE(steps.meta("u_S_unbounded0"));
      CHECK(summary.find("u_S unbounded") == std::string::npos);
    }
  }
}

// A scan sequence's fit as the result (service/sequence_result.cpp): a term of its u_S held at
// the readings' bound (core::SequenceRefineResult::unbounded) puts u_S_bounded_by_data false
// into motion.csv's metadata and the line into summary.txt's notes; none, nothing.
TEST_CASE("sequence result: a u_S the data do not bound is said so in motion.csv's metadata") {
  const core::FourSensorConfig cfg;
  const auto seq = core::ScanSequence::make(core::ScanSequenceKind::reversed_closing, cfg);
  core::SequenceSimOptions so;
  so.seed = 5;
  so.sigma_um = 0.1;
  const auto d =
      core::simulate_four_sensor_sequence(cfg, core::random_smooth_truth(cfg, 5), seq, so);
  core::SequenceRefineResult sr;
  sr.plan = seq.name;
  sr.before = sr.after = core::fit_four_sensor_sequence(cfg, seq, d.m_um);
  auto bounded_meta = [&](const core::SequenceRefineResult& r) {
    io::ResultWriteInfo info;
    service::describe_sequence_result(cfg, seq, r, d.x_mm, info);
    std::optional<std::string> v;
    for (const auto& [k, val] : info.extra_metadata)
      if (k == "u_S_bounded_by_data") v = val;
    bool noted = false;
    for (const auto& n : info.summary_notes)
      noted = noted || n.find("u_S unbounded") != std::string::npos;
    return std::make_pair(v, noted);
  };
  const auto [v0, noted0] = bounded_meta(sr);
  CHECK_FALSE(v0);
  CHECK_FALSE(noted0);
  sr.unbounded = {"u_S unbounded: thermal drift not determined by this plan; declare a bound"};
  sr.report = sr.unbounded;  // as refine_effects puts it into the findings
  const auto [v1, noted1] = bounded_meta(sr);
  CHECK(v1 == std::optional<std::string>("false"));
  CHECK(noted1);
}

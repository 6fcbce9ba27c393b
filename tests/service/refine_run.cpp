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
#include "errsep/io/refine_report.hpp"
#include "errsep/service/sequence_result.hpp"
#include "support/support.hpp"

using namespace errsep;
namespace fs = std::filesystem;

namespace {

// A reversed closing plan's readings (random smooth truth of `seed`, σ 0.1 µm).
struct SequenceScan {
  core::FourSensorConfig cfg;
  core::ScanSequence seq = core::ScanSequence::make(core::ScanSequenceKind::reversed_closing, cfg);
  core::SequenceSimData d;
};
SequenceScan reversed_closing_scan(std::uint64_t seed) {
  SequenceScan s;
  core::SequenceSimOptions so;
  so.seed = seed;
  so.sigma_um = 0.1;
  s.d =
      core::simulate_four_sensor_sequence(s.cfg, core::random_smooth_truth(s.cfg, seed), s.seq, so);
  return s;
}

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
    CHECK(io::refine_role_of(steps, "refine_steps.csv") == io::RefineRole::result);
    CHECK(steps.meta(io::kRefineRoleKey));
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
  const SequenceScan scan = reversed_closing_scan(5);
  const auto& cfg = scan.cfg;
  const auto& seq = scan.seq;
  const auto& d = scan.d;
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

// γ's level (service/sequence_result.cpp): motion.csv's u_gamma_urad is in the fit's gauge (the
// constant e_4 = 0 sets); with a warm-up of every configuration fitted that constant is all but
// undetermined, and the result says so (gamma_level_determined_by_data false, a summary line)
// beside γ's u about its constant and line, which stays the size of the plain fit's.  Without
// fitted effects or with a linear drift: determined, nothing said.
TEST_CASE("sequence result: gamma's level undetermined by a fitted warm-up is said so") {
  const SequenceScan scan = reversed_closing_scan(10);
  const auto& cfg = scan.cfg;
  const auto& seq = scan.seq;
  const auto& d = scan.d;
  const auto rms = [](const Eigen::VectorXd& v) {
    return std::sqrt(v.squaredNorm() / static_cast<double>(v.size()));
  };
  struct Said {
    double ratio = 0, shape_urad = 0;
    std::optional<std::string> determined, shape_meta, angular, angular_U;
    bool noted = false;
  };
  auto said = [&](const Eigen::MatrixXd& extra) {
    core::SequenceRefineResult sr;
    sr.plan = seq.name;
    sr.before = sr.after = core::fit_four_sensor_sequence(cfg, seq, d.m_um, extra);
    io::ResultWriteInfo info;
    service::describe_sequence_result(cfg, seq, sr, d.x_mm, info);
    Said s;
    s.shape_urad = 1e6 * rms(sr.after.u_gamma_rad);
    s.ratio = rms(sr.after.u_gamma_in_gauge_rad()) / rms(sr.after.u_gamma_rad);
    for (const auto& [k, v] : info.extra_metadata)
      if (k == io::kMetaGammaLevelDetermined) s.determined = v;
    for (const auto& [k, v] : info.motion_metadata)
      if (k == io::kMetaUGammaShapeUrad)
        s.shape_meta = v;
      else if (k == io::kMetaAngularDeviationUrad)
        s.angular = v;
      else if (k == io::kMetaAngularDeviationUUrad)
        s.angular_U = v;
    for (const auto& n : info.summary_notes)
      s.noted = s.noted || n.find("gamma's level is not determined") != std::string::npos;
    return s;
  };
  const auto cols = [&](core::SequenceEffectKind k) {
    return core::sequence_effect_columns(k, cfg, seq, 40.0, 1).J;
  };
  const Said plain = said({});
  const Said drift = said(cols(core::SequenceEffectKind::drift));
  const Said warm = said(cols(core::SequenceEffectKind::thermal));
  WARN("u_gamma in the gauge / about its constant and line: plain "
       << plain.ratio << ", drift " << drift.ratio << ", warm-up " << warm.ratio
       << "; about its constant and line (urad RMS): " << plain.shape_urad << ", "
       << drift.shape_urad << ", " << warm.shape_urad);
  for (const Said* s : {&plain, &drift}) {
    CHECK(s->ratio < service::kGammaLevelUndeterminedRatio);
    CHECK_FALSE(s->determined);
    CHECK_FALSE(s->noted);
    CHECK(s->shape_meta);
  }
  CHECK(warm.ratio > service::kGammaLevelUndeterminedRatio);
  CHECK(warm.determined == std::optional<std::string>("false"));
  CHECK(warm.noted);
  CHECK(warm.shape_meta);
  // The shape's u with the warm-up fitted is of the plain fit's size, not the gauge's.
  CHECK(warm.shape_urad < 3.0 * plain.shape_urad);
  // The angular deviation (max - min) with U from γ's covariance is stated in every case; with
  // the warm-up its U stays of the plain fit's order (γ's constant cancels), not the gauge's.
  for (const Said* s : {&plain, &drift, &warm}) {
    REQUIRE(s->angular);
    REQUIRE(s->angular_U);
  }
  CHECK(std::stod(*warm.angular_U) < 3.0 * std::stod(*plain.angular_U));
}

// The refinement on generated cases with one undeclared effect each (issue 16, item 1): random
// smooth profiles per seed (undeclared_effect_simulation.hpp), independent noise on every reading,
// every effect of the library plus two it lacks (a sensor non-linearity, a bump).  A small but
// random, multi-seed version of the table errsep-refine-sweep prints (apps/refine-sweep: >= 20
// seeds per cell at sigma = 0.05, 0.1 and 0.2 um); what it asserts:
//   - clean data: at most 5 % of runs add anything to the model;
//   - an effect of the library: in no run does the S or gamma error grow by more than its stated
//     uncertainty (the RMS of the refined u over the points);
//   - no step moves what one scan cannot see: the constant, line and bow of S after the loop are
//     those of the raw readings' separation (to rounding);
//   - the refined u_S covers 90-99 % of points within 2 u_S on clean data (over the effect cells it
//     does not: printed per cell, see the last test case but one);
//   - an effect detected but not applied is reported so, with its size, and widens u_S;
//   - halving where the effect is identifiable from the plan used (effect_identifiability:
//     computed from the design and sigma-hat, not from the truth): counted and printed, and
//     asserted at >= 80 % over the runs where it holds (see that test case for the figures).
//   - a declared bound (Type B) on an effect one scan cannot identify: u only, stated, covers
//     more (drift on all configurations);
//   - PE2 at sigma 0.2 seed 15 (a far least-squares minimum) is not applied with the
//     identifiability gate (off by default).
// Known not to hold in the full table (errsep-refine-sweep, seeds 1-20, not the seeds here): a
// thermal drift on one configuration taken for a knocked sensor by the gross-error search and
// removed (seed 12 at 0.05 um: S 0.35 -> 1.89 um, u_S 0.46; core/gross_errors, not the effect
// loop).
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "errsep/core/refine_sweep.hpp"
#include "errsep/io/refine_report.hpp"

using namespace errsep::core;

namespace {

// Seeds per cell and noise levels of the ctest sweep (kept small: the whole file runs in about
// the time stated in the report; the full table is errsep-refine-sweep's).
constexpr int kSeeds = 4;
constexpr std::uint64_t kSeed0 = 101;

RefineOptions test_options() {
  RefineOptions o;
  o.residual.mc_samples = 199;  // the least that can reach p < alpha = 0.01 is 100
  return o;
}

struct Pool {
  long points = 0, covered = 0;
  void add(const SweepCell& c) {
    for (const auto& r : c.runs) {
      points += r.points;
      covered += r.covered;
    }
  }
  double fraction() const {
    return points ? static_cast<double>(covered) / static_cast<double>(points) : 0.0;
  }
};

Pool& coverage_pool() {
  static Pool p;
  return p;
}

void print_cell(const SweepCell& c) {
  std::printf("%s\n  %s\n", sweep_row(c).c_str(), coverage_breakdown(c).c_str());
  for (const auto& r : c.runs)
    std::printf(
        "    seed %3llu S %.3f -> %.3f (clean %.3f, u %.3f) g %.2f -> %.2f (u %.2f) "
        "gauge %.2g | %s | %s\n",
        static_cast<unsigned long long>(r.seed), r.S_before_um, r.S_after_um, r.S_clean_um,
        r.u_S_after_um, r.gamma_before_urad, r.gamma_after_urad, r.u_gamma_after_urad,
        r.gauge_change_um, r.model.c_str(), r.description.c_str());
  for (const auto& r : c.runs)
    if (!r.identifiability.empty())
      std::printf("    seed %3llu %s\n", static_cast<unsigned long long>(r.seed),
                  r.identifiability.c_str());
}

// The gauge: a step never moves the constant, line and bow of S.  Rounding only: S is some µm,
// so 1e-9 of the largest error or 1e-9 µm.
void check_gauge(const SweepCell& c) {
  for (const auto& r : c.runs) {
    INFO("seed " << r.seed << ": " << r.description << " -> " << r.model);
    CHECK(r.gauge_change_um <= 1e-9 * std::max(1.0, r.S_before_um));
  }
}

}  // namespace

TEST_CASE("undeclared effects: clean data adds nothing in at least 95 % of runs") {
  const RefineOptions o = test_options();
  int runs = 0, added = 0;
  std::printf("%s\n", sweep_header().c_str());
  for (double sigma : {0.05, 0.1, 0.2}) {
    const SweepCell c = run_sweep_cell(UndeclaredEffect::none, sigma, 2 * kSeeds, kSeed0, o);
    print_cell(c);
    check_gauge(c);
    coverage_pool().add(c);
    for (const auto& r : c.runs) {
      ++runs;
      if (r.added) ++added;
    }
  }
  std::printf("clean: something added in %d of %d runs\n", added, runs);
  CHECK(added * 20 <= runs);
}

// And, over the same runs, halving where the effect is identifiable from the plan used
// (effect_identifiability: the predicted error with the correction at most half the one without,
// from the design, the fit's sigma-hat and the fitted size at its lower confidence bound, never
// from the truth).  errsep-refine-sweep, seeds 1-20 at sigma 0.05/0.1/0.2: halved in 22 of the 23
// runs where it holds (pe1 5/5, gain 1/1, pe2 1/1, periodic 15/16); it holds in few runs at
// these sizes: a positioning or gain error that doubles the clean error is mostly too poorly
// determined by one scan to be halved, and drift, thermal drift and a non-repeating traverse are
// not identifiable from the single plan at all (their undetermined combinations move S).
TEST_CASE("undeclared effects: a library effect never makes S or gamma worse beyond its u",
          "[sweep]") {
  const RefineOptions o = test_options();
  int identifiable = 0, halved = 0;
  std::printf("%s\n", sweep_header().c_str());
  for (const auto e : all_undeclared_effects()) {
    if (library_effect_name(e).empty()) continue;  // none, and the effects the library lacks
    for (double sigma : {0.05, 0.2}) {
      const SweepCell c = run_sweep_cell(e, sigma, kSeeds, kSeed0, o);
      print_cell(c);
      check_gauge(c);
      coverage_pool().add(c);
      for (const auto& r : c.runs) {
        INFO(to_string(e) << " sigma " << sigma << " seed " << r.seed << ": " << r.description
                          << " -> " << r.model);
        CHECK(r.S_after_um <= r.S_before_um + r.u_S_after_um);
        CHECK(r.gamma_after_urad <= r.gamma_before_urad + r.u_gamma_after_urad);
        if (r.identifiable_from_plan) {
          ++identifiable;
          if (r.halved()) ++halved;
        }
      }
    }
  }
  std::printf("identifiable from the plan in %d runs; S and gamma error halved in %d of them\n",
              identifiable, halved);
  REQUIRE(identifiable >= 1);  // the sizes drawn here include cases a step can halve
  CHECK(halved * 5 >= identifiable * 4);
}

TEST_CASE("undeclared effects not in the library: the gauge stays, nothing applied blindly") {
  const RefineOptions o = test_options();
  std::printf("%s\n", sweep_header().c_str());
  for (const auto e : {UndeclaredEffect::nonlinearity, UndeclaredEffect::bump}) {
    const SweepCell c = run_sweep_cell(e, 0.1, kSeeds, kSeed0, o);
    print_cell(c);
    check_gauge(c);
    coverage_pool().add(c);
  }
}

// Coverage of the refined u_S.  Asserted on clean data only: over the effect cells it does NOT
// hold (errsep-refine-sweep, seeds 1-20, prints it per cell, split by what the refine did).  The
// cells that undercover are those whose effect one scan cannot identify: drift (0.36-0.79),
// thermal drift (0.30-0.82), a non-repeating traverse and a bump; there the effect is mostly
// detected and not applied, and u_S is widened by the fitted size of its determined part plus
// the undetermined combinations each as large as the determined ones on average, which
// understates an effect whose size lies mostly in what the scan cannot see (a drift common to
// the configurations).  A plan with redundancy (sequence_refine.hpp) is the remedy, not u.
TEST_CASE("undeclared effects: on clean data the refined u_S covers 90-99 % within 2 u_S") {
  const RefineOptions o = test_options();
  Pool clean;
  for (double sigma : {0.05, 0.1, 0.2})
    clean.add(run_sweep_cell(UndeclaredEffect::none, sigma, 2 * kSeeds, kSeed0 + 50, o));
  std::printf("clean: %ld of %ld points within 2 u_S (%.3f)\n", clean.covered, clean.points,
              clean.fraction());
  const Pool& pool = coverage_pool();
  if (pool.points > 0)
    std::printf("not asserted: over the cases run before in this process %ld of %ld (%.3f)\n",
                pool.covered, pool.points, pool.fraction());
  REQUIRE(clean.points > 0);
  CHECK(clean.fraction() >= 0.90);
  CHECK(clean.fraction() <= 0.99);
}

// An effect the loop detects but does not apply: reported as such with its size and what it adds
// to u_S, and u_S widened by it (never narrower than the raw separation's), the gauge unchanged.
TEST_CASE("undeclared effects: detected, not applied: reported and carried in u_S") {
  const RefineOptions o = test_options();
  int found = 0;
  for (std::uint64_t seed = 1; seed <= 20 && found < 3; ++seed) {
    UndeclaredCaseOptions co;
    co.sigma_um = 0.2;
    co.seed = seed;
    const UndeclaredCase c = simulate_undeclared(UndeclaredEffect::gain, co);
    const RefineResult r = refine_four_sensor(c.cfg, c.m_um, c.t_s, o);
    REQUIRE(r.applied.size() == r.effects.size());
    REQUIRE(r.verdicts.size() == r.effects.size());
    for (std::size_t e = 0; e < r.effects.size(); ++e) {
      if (r.applied[e]) continue;
      ++found;
      const std::string& v = r.verdicts[e];
      INFO("seed " << seed << ": " << v);
      CHECK(v.find(" detected (") != std::string::npos);
      CHECK(v.find(" +- ") != std::string::npos);
      CHECK(v.find(": not applied, adds ") != std::string::npos);
      CHECK(v.find(" um to u_S") != std::string::npos);
      const std::string text = errsep::io::format_refine_text(r);
      CHECK(text.find("NOT APPLIED: " + v) != std::string::npos);
      // Not applied: S and gamma are the raw separation's, u_S only wider.
      REQUIRE(r.after.u_S_um.size() == r.before.u_S_um.size());
      CHECK((r.after.S_um - r.before.S_um).cwiseAbs().maxCoeff() <=
            1e-9 * std::max(1.0, r.before.S_um.cwiseAbs().maxCoeff()));
      CHECK((r.after.u_S_um.array() >= r.before.u_S_um.array() * (1 - 1e-12)).all());
      CHECK(r.after.u_S_um.squaredNorm() > r.before.u_S_um.squaredNorm());
      std::printf("seed %llu: %s\n", static_cast<unsigned long long>(seed), v.c_str());
    }
  }
  CHECK(found >= 1);
}

// A declared bound (RefineOptions::declared, a Type B term): what one scan cannot identify of a
// drift on every configuration (three of its four rates lie in what f, S, gamma and e absorb) no
// data-driven widening can cover (u_S without it: 0.52-0.59 of the points within 2 u_S in
// errsep-refine-sweep's drift_all cells, seeds 1-20).  Declared within +-0.03 um/s per rate (a
// sensor's drift specification), the bound enters u only: S and gamma are unchanged, u_S never
// narrower (wider wherever the data's own guess of the undetermined part is smaller), the result
// states the term, and more points are covered.  Measured here (seeds 101-108, sigma 0.1): clean
// 0.974 -> 1.000 (u_S x7.9: 4.1 um rms for S errors of 0.1-0.4 um), drift on all configurations
// 0.673 -> 0.891.  Not asserted: 90-99 %.  The rectangular distribution of a bound (GUM 4.3.7,
// variance b^2/3) understates rates that lie near the bound more often than it assumes (the
// generator draws |a| in [b/3, b]: mean square 0.48 b^2, not 0.33 b^2), and it overcovers clean
// data whatever they show.  A closing or reversed plan identifies the drift instead
// (core/sequence_refine asserts 0.90-0.99 there); the bound is for a single scan.
TEST_CASE("undeclared effects: a declared drift bound (Type B) covers what one scan cannot see",
          "[sweep]") {
  RefineOptions plain = test_options();
  RefineOptions declared = plain;
  declared.declared = {{"drift", 0.03}};
  REQUIRE(declared.is_valid());
  for (auto effect : {UndeclaredEffect::none, UndeclaredEffect::drift_all}) {
    const SweepCell without = run_sweep_cell(effect, 0.1, 2 * kSeeds, kSeed0, plain);
    const SweepCell with = run_sweep_cell(effect, 0.1, 2 * kSeeds, kSeed0, declared);
    print_cell(with);
    std::printf(
        "%s, sigma 0.1, drift declared within +-0.03 um/s: coverage %.3f (without the "
        "bound %.3f)\n",
        to_string(effect), with.coverage(), without.coverage());
    REQUIRE(with.runs.size() == without.runs.size());
    for (std::size_t k = 0; k < with.runs.size(); ++k) {
      const SweepRun &a = with.runs[k], &b = without.runs[k];
      INFO(to_string(effect) << " seed " << a.seed << ": u_S " << b.u_S_after_um << " -> "
                             << a.u_S_after_um);
      CHECK(a.S_after_um == Approx(b.S_after_um).epsilon(1e-9));
      CHECK(a.gamma_after_urad == Approx(b.gamma_after_urad).epsilon(1e-9));
      CHECK(a.u_S_after_um >= b.u_S_after_um * (1 - 1e-12));
      if (effect == UndeclaredEffect::none) CHECK(a.u_S_after_um > b.u_S_after_um);
    }
    CHECK(with.coverage() > without.coverage());
  }
  // Stated in the result, and the raw separation untouched.
  UndeclaredCaseOptions co;
  co.sigma_um = 0.1;
  co.seed = kSeed0;
  const UndeclaredCase c = simulate_undeclared(UndeclaredEffect::none, co);
  const RefineResult r = refine_four_sensor(c.cfg, c.m_um, c.t_s, declared);
  const RefineResult r0 = refine_four_sensor(c.cfg, c.m_um, c.t_s, plain);
  REQUIRE(r.declared_notes.size() == 1);
  std::printf("%s\n", r.declared_notes.front().c_str());
  CHECK(r.declared_notes.front().find("drift declared within +-0.03") != std::string::npos);
  CHECK(r.declared_notes.front().find("Type B") != std::string::npos);
  REQUIRE(r.u_S_declared_um.size() == r.after.u_S_um.size());
  CHECK(r.u_S_declared_um.minCoeff() >= 0.0);
  CHECK(r.u_S_declared_um.maxCoeff() > 0.0);
  CHECK((r.before.u_S_um - r0.before.u_S_um).cwiseAbs().maxCoeff() <= 1e-12);
  CHECK(r0.u_S_declared_um.isZero());
  // u_S² is the plain refined u_S² plus the declared term's, point by point.
  CHECK(((r.after.u_S_um.array().square() - r0.after.u_S_um.array().square() -
          r.u_S_declared_um.array().square())
             .abs() <= 1e-9 * r.after.u_S_um.array().square())
            .all());
}

TEST_CASE("undeclared effects: a declared bound must name a library effect and be positive") {
  RefineOptions o;
  std::string why;
  o.declared = {{"sensor_drift", 0.03}};
  CHECK_FALSE(o.is_valid(&why));
  CHECK(why.find("unknown effect 'sensor_drift'") != std::string::npos);
  CHECK(why.find("drift") != std::string::npos);
  o.declared = {{"drift", 0.0}};
  CHECK_FALSE(o.is_valid(&why));
  CHECK(why.find("'drift' = 0") != std::string::npos);
  o.declared = {{"thermal", 5.0}, {"traverse", 2.0}};
  CHECK(o.is_valid(&why));
}

// The last library-effect run made worse beyond its u in errsep-refine-sweep (seeds 1-20): PE2 at
// sigma 0.2, seed 15.  Its least-squares minimum is far from the truth (c2 = 3094 +- 540 um for a
// true 795; fit_effects started at the truth ends there too, so no second start helps), and the
// decision's linearisation there promised V/B = 0.015; the correction at the fit changes gamma
// by 217 urad rms where that linearisation says 96.  Counting what the linearisation misses in
// the decision (step_decision.hpp QuantityImpact::remainder) declines it by default (V 1.1e6
// against B 2.3e4); gated on identifiability (RefineOptions::apply_requires_identifiable) it is
// not applied either.  Either way it is reported, carried in u, and the gauge is untouched.
TEST_CASE("undeclared effects: PE2 at a far minimum is not applied, gated or not") {
  UndeclaredCaseOptions co;
  co.sigma_um = 0.2;
  co.seed = 15;
  const RefineOptions o = test_options();
  RefineOptions gated = o;
  gated.apply_requires_identifiable = true;
  for (const RefineOptions& opts : {o, gated}) {
    const SweepRun run = evaluate_refine_run(UndeclaredEffect::pe2, co, opts);
    std::printf(
        "PE2 sigma 0.2 seed 15%s: S %.3f -> %.3f um (u %.3f), gamma %.1f -> %.1f urad (u %.1f)"
        "\n  %s\n  %s\n",
        opts.apply_requires_identifiable ? " (gated)" : "", run.S_before_um, run.S_after_um,
        run.u_S_after_um, run.gamma_before_urad, run.gamma_after_urad, run.u_gamma_after_urad,
        run.verdicts.c_str(), run.identifiability.c_str());
    INFO(run.verdicts);
    CHECK_FALSE(run.worse_beyond_u());
    CHECK_FALSE(run.applied);
    CHECK(run.gauge_change_um <= 1e-9 * std::max(1.0, run.S_before_um));
    REQUIRE(run.added);  // detected: it is the decision that declines it
    CHECK(run.verdicts.find("pe2 detected") != std::string::npos);
    CHECK(run.verdicts.find("not linear in its parameters over the step") != std::string::npos);
    CHECK(run.u_S_after_um > run.u_S_before_um);
  }
}

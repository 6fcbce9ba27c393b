// Issue 16, item 2: measuring so the missing effect shows.  A scan sequence with redundancy
// (closing pass, reversed traverses) makes a drift and a non-repeating traverse visible in the
// residual; the single scan cannot, and says so.  Random smooth profiles per seed (several
// harmonics of S, gamma and f with random periods, amplitudes and phases), independent noise
// sigma = 0.1 um on every reading, effect sizes and which configuration drawn per seed:
//   drift_one / drift_all      0.01-0.03 um/s, one configuration / each its own rate
//   thermal_one / thermal_all  2-5 um, tau 20-80 s (warm-up from the start of the scan)
//   traverse                   S bending in proportion to time: P2 and P3 of 1-2 um each at the
//                              last traverse (the truth is the first traverse's S)
// Errors of S are RMS after removing its best-fit constant, line and bow (what no scan sees).
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "errsep/core/four_sensor_sequence_simulation.hpp"
#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/core/refine.hpp"
#include "errsep/core/sequence_refine.hpp"
#include "errsep/core/undeclared_effect_simulation.hpp"

using namespace errsep::core;

namespace {

constexpr int kSeeds = 20;
constexpr double kSigma = 0.1;

enum class Case { none, drift_one, drift_all, thermal_one, thermal_all, traverse };
const char* name(Case c) {
  switch (c) {
    case Case::none:
      return "none";
    case Case::drift_one:
      return "drift_one";
    case Case::drift_all:
      return "drift_all";
    case Case::thermal_one:
      return "thermal_one";
    case Case::thermal_all:
      return "thermal_all";
    case Case::traverse:
      return "traverse";
  }
  return "?";
}
SequenceEffectKind kind_of(Case c) {
  if (c == Case::thermal_one || c == Case::thermal_all) return SequenceEffectKind::thermal;
  if (c == Case::traverse) return SequenceEffectKind::traverse;
  return SequenceEffectKind::drift;
}

SequenceEffects draw_effects(Case c, std::uint64_t seed, const FourSensorConfig& cfg) {
  std::mt19937_64 rng(seed * 7919 + 17);
  auto uni = [&](double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); };
  auto sign = [&] { return uni(0, 1) < 0.5 ? -1.0 : 1.0; };
  const int which = std::uniform_int_distribution<int>(0, 3)(rng);
  SequenceEffects e;
  const bool one = c == Case::drift_one || c == Case::thermal_one;
  for (int i = 0; i < 4; ++i) {
    if (one && i != which) continue;
    const auto si = static_cast<std::size_t>(i);
    if (c == Case::drift_one || c == Case::drift_all)
      e.drift_um_per_s[si] = sign() * uni(0.01, 0.03);
    if (c == Case::thermal_one || c == Case::thermal_all) e.thermal_um[si] = sign() * uni(2.0, 5.0);
  }
  e.thermal_tau_s = uni(20.0, 80.0);
  if (c == Case::traverse) {
    const double a2 = sign() * uni(1.0, 2.0), a3 = sign() * uni(1.0, 2.0);
    const double L = cfg.travel_mm();
    e.S_change_um = [a2, a3, L](int, double x) {
      const double u = 2.0 * x / L - 1.0;
      return a2 * 0.5 * (3 * u * u - 1) + a3 * 0.5 * (5 * u * u * u - 3 * u);
    };
  }
  return e;
}

struct Run {
  bool identified = false, any_added = false, not_identifiable_reported = false;
  double err_clean = 0, err_before = 0, err_after = 0;
  double covered = 0, points = 0;
};

double s_error(const Eigen::VectorXd& S, const Eigen::VectorXd& truth) {
  const Eigen::VectorXd d = remove_polynomial(S - truth, 2);
  return std::sqrt(d.squaredNorm() / static_cast<double>(d.size()));
}

Run run_case(Case c, ScanSequenceKind plan, std::uint64_t seed) {
  FourSensorConfig cfg;  // Zhao 2019 Example 1 geometry
  const SlidewayTruth truth =
      random_smooth_truth(cfg, seed, UndeclaredCaseOptions::wavy_reference());
  const ScanSequence seq = ScanSequence::make(plan, cfg);
  SequenceSimOptions so;
  so.sigma_um = kSigma;
  so.seed = seed;
  SequenceEffects fx = draw_effects(c, seed, cfg);
  if (fx.S_change_um) {  // in proportion to the traverse's mid-time, full size at the last one
    const Eigen::VectorXd mid = seq.times_s(cfg).colwise().mean().transpose();
    const double span = mid.maxCoeff() - mid(0);
    auto shape = fx.S_change_um;
    fx.S_change_um = [shape, mid, span](int k, double x) {
      return (mid(k) - mid(0)) / span * shape(k, x);
    };
  }
  so.effects = fx;
  const SequenceSimData d = simulate_four_sensor_sequence(cfg, truth, seq, so);
  const SequenceRefineResult r = refine_four_sensor_sequence(cfg, seq, d.m_um);
  Run out;
  out.any_added = !r.added.empty();
  if (c != Case::none) out.identified = r.identified(kind_of(c));
  const std::string needle =
      std::string(to_string(kind_of(c))) + ": not identifiable from this plan";
  for (const auto& line : r.report)
    if (line.rfind(needle, 0) == 0) out.not_identifiable_reported = true;
  out.err_clean = s_error(fit_four_sensor_sequence(cfg, seq, d.m_clean_um).S_um, d.S_um);
  out.err_before = s_error(r.before.S_um, d.S_um);
  out.err_after = s_error(r.after.S_um, d.S_um);
  const Eigen::VectorXd dev = remove_polynomial(r.after.S_um - d.S_um, 2);
  for (Eigen::Index n = 0; n < dev.size(); ++n) {
    out.points += 1;
    if (std::abs(dev(n)) <= 2.0 * r.after.u_S_um(n)) out.covered += 1;
  }
  return out;
}

struct Cell {
  int identified = 0, halved = 0, worse = 0, reported = 0, added = 0;
  std::vector<double> clean, before, after;
  double covered = 0, points = 0;
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}
double worst(const std::vector<double>& v) {
  return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end());
}

Cell run_cell(Case c, ScanSequenceKind plan) {
  Cell cell;
  for (int s = 1; s <= kSeeds; ++s) {
    const Run r = run_case(c, plan, 1000 + static_cast<std::uint64_t>(s));
    cell.identified += r.identified;
    cell.added += r.any_added;
    cell.reported += r.not_identifiable_reported;
    cell.halved += r.err_after <= 0.5 * r.err_before;
    cell.worse += r.err_after > r.err_before;
    cell.clean.push_back(r.err_clean);
    cell.before.push_back(r.err_before);
    cell.after.push_back(r.err_after);
    cell.covered += r.covered;
    cell.points += r.points;
  }
  std::printf(
      "%-12s %-13s identified %2d/%d  halved %2d  worse %2d  'not identifiable' %2d  added %2d | "
      "S err um clean %.3f, before %.3f (worst %.3f), after %.3f (worst %.3f) | cov 2u %.3f\n",
      name(c), to_string(plan), cell.identified, kSeeds, cell.halved, cell.worse, cell.reported,
      cell.added, median(cell.clean), median(cell.before), worst(cell.before), median(cell.after),
      worst(cell.after), cell.covered / cell.points);
  return cell;
}

}  // namespace

TEST_CASE("scan sequences: times, redundancy, validation") {
  FourSensorConfig cfg;
  const auto single = ScanSequence::make(ScanSequenceKind::single, cfg, 10.0, 2.0);
  const auto closing = ScanSequence::make(ScanSequenceKind::closing_pass, cfg, 10.0, 2.0);
  const auto reversed = ScanSequence::make(ScanSequenceKind::reversed, cfg, 10.0, 2.0);
  CHECK(single.size() == 4);
  CHECK_FALSE(single.redundant());
  CHECK(closing.size() == 5);
  CHECK(closing.traverses.back().configuration == 0);
  CHECK(reversed.size() == 8);
  const Eigen::MatrixXd t = reversed.times_s(cfg);
  const int P = cfg.positions();
  const double dur = (P - 1) * cfg.dx_mm / 10.0;
  CHECK(t(0, 1) == Approx(dur + 2.0 + dur));  // the backward pass reads x_0 last
  CHECK(t(P - 1, 1) == Approx(dur + 2.0));
  std::string why;
  ScanSequence bad = single;
  bad.traverses.pop_back();
  CHECK_FALSE(bad.is_valid(&why));
  CHECK(why.find("configuration 4") != std::string::npos);
}

TEST_CASE("sequence fit: the single plan equals the refine base; u_S covers clean data") {
  FourSensorConfig cfg;
  long covered = 0, points = 0;
  for (auto plan : {ScanSequenceKind::single, ScanSequenceKind::closing_pass,
                    ScanSequenceKind::reversed, ScanSequenceKind::interleaved}) {
    for (std::uint64_t seed = 1; seed <= 10; ++seed) {
      const SlidewayTruth truth = random_smooth_truth(cfg, seed);
      const ScanSequence seq = ScanSequence::make(plan, cfg);
      SequenceSimOptions so;
      so.sigma_um = kSigma;
      so.seed = seed;
      const auto d = simulate_four_sensor_sequence(cfg, truth, seq, so);
      const auto fit = fit_four_sensor_sequence(cfg, seq, d.m_um);
      const Eigen::VectorXd dev = remove_polynomial(fit.S_um - d.S_um, 2);
      for (Eigen::Index n = 0; n < dev.size(); ++n, ++points)
        covered += std::abs(dev(n)) <= 2.0 * fit.u_S_um(n);
    }
  }
  const double frac = static_cast<double>(covered) / static_cast<double>(points);
  std::printf("clean coverage of 2 u_S over 4 plans x 10 seeds: %.3f (%ld points)\n", frac, points);
  CHECK(frac >= 0.90);
  CHECK(frac <= 0.99);
}

TEST_CASE("must-show: drift and a non-repeating traverse identified from a redundant plan") {
  std::printf("identifiability from the plan (undetermined S fraction):\n");
  FourSensorConfig cfg;
  for (auto plan : {ScanSequenceKind::single, ScanSequenceKind::closing_pass,
                    ScanSequenceKind::reversed, ScanSequenceKind::interleaved})
    for (const auto& id : sequence_identifiability(cfg, ScanSequence::make(plan, cfg)))
      std::printf("  %-13s %-24s %2d/%2d directions, undetermined S %.3f -> %s\n", to_string(plan),
                  to_string(id.kind), id.identifiable, id.parameters, id.undetermined_S_fraction,
                  id.identifiable_from_plan ? "identifiable" : "NOT identifiable");
  for (auto plan :
       {ScanSequenceKind::single, ScanSequenceKind::closing_pass, ScanSequenceKind::reversed})
    for (auto c : {Case::none, Case::drift_one, Case::drift_all, Case::thermal_one,
                   Case::thermal_all, Case::traverse})
      run_cell(c, plan);
}

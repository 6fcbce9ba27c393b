// The residual traced against what a scan records, and spikes and steps kept out of S (issue 16,
// item 3): residual_trace.hpp, gross_errors.hpp, repeat_steps.hpp and their use at the end of
// refine_four_sensor.  Random cases only (undeclared_effect_simulation.hpp and random_smooth_truth:
// several harmonics of S, γ and f with random phases and amplitudes per seed, independent noise
// on every reading).  The tables print, per cell: found, the S error (bow removed) before and
// after (median, worst), runs made worse beyond the stated u, runs with more than a fifth of
// their points outside 2 u_S (and of them, runs where nothing was found), and the coverage of
// u_S's shape (points within 2 u_S, bow removed from error and covariance) before and after.
// What it asserts:
//   - calibration: on 120 clean runs the trace (α = 0.05, Bonferroni over its ten tests), the
//     gross-error search (α = 0.05) and the repeat-step search (120 clean reversed-plan scans)
//     call something in at most α plus two binomial standard deviations of the runs, and the
//     single tests' p-values fall below α at about the rate α;
//   - non-linearity (not in the library; 40 seeds per σ, sized to double the clean S error):
//     clean false alarms <= 5 %; found in >= 80 % of the runs where the residual can show it
//     (δ = ‖Π·Δm‖/σ >= 4.5), and in each σ cell no less often than the most powerful test of the
//     known signature would on average (minus three binomial sd); when found, corrected by
//     separate_without_nonlinearity (sensor_nonlinearity.hpp) or carried in u, never worse
//     beyond u.  NOT reached, printed: found in 45, 45, 40 % of all runs (the issue asks 80 %):
//     only ~5 % of the effect's norm is outside what the model absorbs (δ median 2.7-2.9); in
//     11-12 of 40 runs more than a fifth of S lies outside 2 u_S with nothing found (a
//     non-linearity that does not show does hurt), coverage 0.66 before, 0.79-0.81 after.
//   - spikes and steps, σ = 0.05, 0.1, 0.2 µm, 20 seeds per cell: a spike (5-20 σ on one reading)
//     found at its reading and removed in >= 80 % of the runs where the residual can show it
//     (size·‖Π z‖ >= 6 σ: configuration 4's readings are nearly fitted by γ); a step located
//     within one position in >= 80 % of those runs; never worse beyond u; an ambiguous one
//     reported with every plausible configuration ("in one of the configurations ...; this scan
//     cannot tell which"), the truth among them in >= 80 %; the shape coverage of u_S pooled over
//     the spike and step cells in 0.90-0.99.  Printed: a single scan attributes a step in 9, 3, 1
//     of 20 runs (the four configurations' steps leave one residual direction away from the step,
//     repeat_steps.hpp), step cells alone cover 0.82-0.89 (mostly steps not found at all);
//   - a knock in a reversed plan (each configuration measured twice): its configuration named in
//     >= 80 % of runs per σ, the single scan with that attribution never worse beyond u.
//   - a recorded temperature that the residual follows is found, none is found without it; the
//     refine's report line carries the spike and its `after` is the separation without it.
#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "errsep/core/four_sensor_sequence_simulation.hpp"
#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/core/gross_errors.hpp"
#include "errsep/core/refine.hpp"
#include "errsep/core/repeat_steps.hpp"
#include "errsep/core/residual_trace.hpp"
#include "errsep/core/sensor_nonlinearity.hpp"
#include "errsep/core/undeclared_effect_simulation.hpp"

using namespace errsep::core;

namespace {

double S_error(const Eigen::VectorXd& S, const Eigen::VectorXd& truth) {
  const Eigen::VectorXd d = remove_polynomial(S - truth, 2);
  return std::sqrt(d.squaredNorm() / static_cast<double>(d.size()));
}

double rms(const Eigen::VectorXd& v) {
  return v.size() ? std::sqrt(v.squaredNorm() / static_cast<double>(v.size())) : 0.0;
}

UndeclaredCase clean_case(double sigma, std::uint64_t seed,
                          UndeclaredEffect e = UndeclaredEffect::none, double size = 1.0) {
  UndeclaredCaseOptions o;
  o.sigma_um = sigma;
  o.seed = seed;
  o.size = size;
  return simulate_undeclared(e, o);
}

bool level_found(const ResidualTrace& t) {
  for (const auto& d : t.tests)
    if (d.significant && d.variable.rfind("reading level", 0) == 0) return true;
  return false;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

TEST_CASE("on clean data the trace and the gross-error search call something in at most alpha") {
  const double alpha = 0.05;
  ResidualTraceOptions to;
  to.alpha = alpha;
  GrossErrorOptions go;
  go.alpha = alpha;
  int runs = 0, trace_alarms = 0, gross_alarms = 0, tests = 0, single = 0;
  int signature_tests = 0, signature = 0;  // the non-linearity's score tests alone
  for (double sigma : {0.05, 0.1, 0.2})
    for (std::uint64_t seed = 1; seed <= 40; ++seed) {
      const UndeclaredCase c = clean_case(sigma, 1000 + seed);
      const ResidualSpace space(c.cfg);
      const ResidualTrace t = trace_residual(space, c.m_um, {c.t_s, {}, {}}, to);
      const GrossErrorScan g = find_gross_errors(space, c.m_um, go);
      ++runs;
      trace_alarms += t.depends ? 1 : 0;
      gross_alarms += g.found() ? 1 : 0;
      for (const auto& d : t.tests)
        if (d.tested) {
          ++tests;
          single += d.p_value < alpha ? 1 : 0;
          if (d.variable.find("non-linearity") != std::string::npos) {
            ++signature_tests;
            signature += d.p_value < alpha ? 1 : 0;
          }
        }
    }
  const double bound = alpha + 2.0 * std::sqrt(alpha * (1 - alpha) / runs);
  std::printf(
      "clean, %d runs at alpha = %.2f: trace alarms %d (%.3f), gross-error alarms %d "
      "(%.3f), bound %.3f; single tests below alpha %d of %d (%.3f)\n",
      runs, alpha, trace_alarms, static_cast<double>(trace_alarms) / runs, gross_alarms,
      static_cast<double>(gross_alarms) / runs, bound, single, tests,
      static_cast<double>(single) / tests);
  std::printf("the non-linearity score tests alone: %d of %d below alpha (%.3f, bound %.3f)\n",
              signature, signature_tests, double(signature) / signature_tests,
              alpha + 2.0 * std::sqrt(alpha * (1 - alpha) / signature_tests));
  CHECK(double(signature) / signature_tests <=
        alpha + 2.0 * std::sqrt(alpha * (1 - alpha) / signature_tests));
  CHECK(static_cast<double>(trace_alarms) / runs <= bound);
  CHECK(static_cast<double>(gross_alarms) / runs <= bound);
  // Each test alone at its nominal level (not only the Bonferroni family).
  CHECK(static_cast<double>(single) / tests <=
        alpha + 2.0 * std::sqrt(alpha * (1 - alpha) / tests) * 2.0);
}

namespace {

// One cell of the must-show table: S errors (bow removed) without and with the loop, how often
// the loop made S worse beyond its stated u, and the coverage of u_S (points within 2 u_S).
struct Cell {
  int runs = 0, found = 0, worse = 0, beyond = 0, beyond_not_found = 0;
  long points = 0, covered_before = 0, covered_after = 0;
  std::vector<double> before, after;
  void add(const FourSensorResult& b, const FourSensorResult& a, const Eigen::VectorXd& S_truth,
           bool found_it) {
    ++runs;
    found += found_it ? 1 : 0;
    const double eb = S_error(b.S_um, S_truth), ea = S_error(a.S_um, S_truth);
    before.push_back(eb);
    after.push_back(ea);
    worse += ea > eb + rms(a.u_S_um) ? 1 : 0;
    // Coverage of the shape: the error and the covariance with the constant, line and bow of S
    // removed (what one scan cannot see; the gauge is not part of the result's claim).
    covered_before += shape_covered(b, S_truth);
    const long in = shape_covered(a, S_truth);
    covered_after += in;
    points += a.S_um.size();
    // "S error beyond 2 u_S": more than a fifth of the run's points outside 2 u_S (a stated u
    // that holds leaves about 5 %).
    const bool out = 5 * in < 4 * a.S_um.size();
    beyond += out ? 1 : 0;
    beyond_not_found += out && !found_it ? 1 : 0;
  }
  static long shape_covered(const FourSensorResult& r, const Eigen::VectorXd& S_truth) {
    const Eigen::VectorXd d = remove_polynomial(r.S_um - S_truth, 2);
    std::vector<int> all(static_cast<std::size_t>(d.size()));
    for (std::size_t n = 0; n < all.size(); ++n)
      all[n] = static_cast<int>(n);
    REQUIRE(r.covariance);
    const Eigen::MatrixXd V = r.covariance->covariance_S(all);
    const Eigen::MatrixXd Vs = remove_polynomial(remove_polynomial(V, 2).transpose(), 2);
    long in = 0;
    for (Eigen::Index n = 0; n < d.size(); ++n)
      in += std::abs(d(n)) <= 2.0 * std::sqrt(std::max(0.0, Vs(n, n))) ? 1 : 0;
    return in;
  }
  double worst(const std::vector<double>& v) const {
    return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end());
  }
  double coverage_before() const { return points ? double(covered_before) / double(points) : 0; }
  double coverage_after() const { return points ? double(covered_after) / double(points) : 0; }
  void print(const char* name, double sigma, const char* extra = "") const {
    std::printf(
        "%-13s %4.2f | %2d/%-2d | %6.3f %6.3f | %6.3f %6.3f | %2d | %2d (%2d) | %.3f %.3f | %s\n",
        name, sigma, found, runs, median(before), worst(before), median(after), worst(after), worse,
        beyond, beyond_not_found, coverage_before(), coverage_after(), extra);
  }
};

void print_header() {
  std::printf(
      "%-13s %4s | %5s | %-13s | %-13s | %2s | %7s | %-11s |\n"
      "%-13s %4s | %5s | %-13s | %-13s | %2s | %7s | %-11s |\n",
      "cell", "sigma", "found", "S err before", "S err after", "w", "beyond", "cov 2u_S", "", "",
      "", " median worst", " median worst", "", "(unfnd)", "before after");
}

// Two-sided normal tail probability P(|Z + delta| > z).
double power_normal(double delta, double z) {
  return 0.5 * std::erfc((z - delta) / std::sqrt(2.0)) +
         0.5 * std::erfc((z + delta) / std::sqrt(2.0));
}

}  // namespace

TEST_CASE("must-show: a non-linearity found where the residual can show it", "[sweep]") {
  // Sized with σ so that it at least doubles the clean S error (printed): 25σ·(2-4 %) of the
  // readings' half range at its ends.  More seeds than the other cells: the trace is cheap.
  constexpr int kSeeds = 40;
  constexpr double kNonlinearityPerSigma = 25.0;
  // What the residual can show: δ = ‖Π·Δm‖/σ, the non-centrality of the score test with the
  // non-linearity's own signature.  At δ >= 4.5 a one-degree-of-freedom test at 0.01 / 10
  // (the trace's Bonferroni over its ten tests: |t| > 3.48) has power >= 0.86.
  constexpr double kShows = 4.5;
  const FourSensorOptions solve;
  std::printf("non-linearity (not in the effect library), %d seeds per sigma\n", kSeeds);
  print_header();
  int shows_all = 0, shows_found_all = 0;
  for (double sigma : {0.05, 0.1, 0.2}) {
    Cell cell, clean;
    int shows = 0, shows_found = 0, not_white = 0, applied = 0;
    std::vector<double> delta, delta_rezero, visible;
    double expected = 0;
    for (int s = 1; s <= kSeeds; ++s) {
      const std::uint64_t seed = 500 + static_cast<std::uint64_t>(s);
      const UndeclaredCase c =
          clean_case(sigma, seed, UndeclaredEffect::nonlinearity, kNonlinearityPerSigma * sigma);
      const ResidualSpace space(c.cfg);
      const ResidualTrace tc = trace_residual(space, c.m_clean_um, {c.t_s, {}, {}});
      const ResidualTrace t = trace_residual(space, c.m_um, {c.t_s, {}, {}});
      const bool found = level_found(t);
      ResidualAnalysisOptions ro;
      ro.mc_samples = 199;
      const bool white = analyse_residual(space, c.m_um, c.t_s, ro).whiteness.white;
      not_white += (t.depends || !white) ? 1 : 0;
      const FourSensorResult rc = separate_four_sensor(c.cfg, c.m_clean_um, solve);
      const FourSensorResult r = separate_four_sensor(c.cfg, c.m_um, solve);
      clean.add(rc, rc, c.S_um, tc.depends);
      NonlinearityStep step;
      const FourSensorResult after =
          separate_without_nonlinearity(c.cfg, c.m_um, t, r, solve, &step);
      applied += step.applied ? 1 : 0;
      cell.add(r, after, c.S_um, found);
      const Eigen::MatrixXd dm = c.m_um - c.m_clean_um;
      const double d =
          space.project_out(reduce_columns(c.cfg, Eigen::MatrixXd(stack_readings(dm)))).norm() /
          sigma;
      delta.push_back(d);
      visible.push_back(
          space.project_out(reduce_columns(c.cfg, Eigen::MatrixXd(stack_readings(dm)))).norm() /
          dm.norm());
      expected += power_normal(d, 3.48);
      if (d >= kShows) {
        ++shows;
        shows_found += found ? 1 : 0;
      }
      // The plan that would show it: configuration 1 measured again with the sensor re-zeroed
      // by one reading range Δ (the non-linearity does not repeat): the difference of the two
      // passes is 2κΔ·(r − r̄) + const + noise (σ√2 per reading), a slope on the whole traverse.
      const Eigen::VectorXd r1 =
          c.m_clean_um.col(0).array() - 0.5 * (c.m_clean_um.maxCoeff() + c.m_clean_um.minCoeff());
      const Eigen::VectorXd a = r1.array().square();
      const double kappa = dm.col(0).dot(a) / a.squaredNorm();  // the drawn κ (dm = κ·a exactly)
      const double range = c.m_clean_um.maxCoeff() - c.m_clean_um.minCoeff();
      const Eigen::VectorXd rc1 = r1.array() - r1.mean();
      delta_rezero.push_back(2.0 * std::abs(kappa) * range * rc1.norm() / (std::sqrt(2.0) * sigma));
    }
    clean.print("clean", sigma);
    char extra[200];
    std::snprintf(extra, sizeof extra,
                  "corrected %d; not white %d/%d; S error x%.1f of clean; delta median %.2f "
                  "sigma (%.0f %% of the effect visible)",
                  applied, not_white, kSeeds, median(cell.before) / median(clean.before),
                  median(delta), 100.0 * median(visible));
    cell.print("nonlinearity", sigma, extra);
    std::printf(
        "    shows (delta >= %.1f): %d of %d runs, found in %d; the best test of this size finds "
        "%.1f of %d on average; a re-zeroed closing pass would show it at delta median %.0f\n",
        kShows, shows, kSeeds, shows_found, expected, kSeeds, median(delta_rezero));
    CHECK(clean.found <= kSeeds / 20);  // clean false alarms <= 5 %
    CHECK(cell.worse == 0);             // the correction, when applied, never worse beyond u
    shows_all += shows;
    shows_found_all += shows_found;
    // Found no less often than the most powerful test of this alternative could on average
    // (three binomial standard deviations below its expected count).
    CHECK(cell.found >= expected - 3.0 * std::sqrt(expected * (1.0 - expected / kSeeds)));
  }
  std::printf("non-linearity where the residual shows it (delta >= %.1f): found %d of %d\n", kShows,
              shows_found_all, shows_all);
  CHECK(shows_all >= 5);
  CHECK(shows_found_all * 10 >= 8 * shows_all);
}

TEST_CASE("must-show: spikes and steps found, removed when attributed, else carried in u_S") {
  constexpr int kSeeds = 20;
  constexpr double kVisible = 6.0;  // |size|·‖Π z‖/σ: what the residual can show
  const FourSensorOptions solve;
  std::printf("spikes (5-20 sigma on one reading) and steps (one configuration, 0.5-1.5 um)\n");
  print_header();
  long points_all = 0, covered_all = 0;
  int ambiguous_all = 0, holds_all = 0;
  for (double sigma : {0.05, 0.1, 0.2}) {
    for (const char* kind : {"spike", "step"}) {
      const bool is_spike = std::string(kind) == "spike";
      Cell cell;
      int right = 0, visible = 0, visible_right = 0, visible_located = 0, ambiguous = 0;
      int ambiguous_holds_truth = 0;
      for (int s = 1; s <= kSeeds; ++s) {
        const std::uint64_t seed = 700 + static_cast<std::uint64_t>(s);
        const UndeclaredCase c = clean_case(sigma, seed);
        std::mt19937_64 rng(seed * 31 + (is_spike ? 1 : 2));
        std::uniform_int_distribution<int> conf(0, 3);
        const int P = c.cfg.positions();
        Eigen::MatrixXd m = c.m_um;
        const int ci = conf(rng);
        int n0 = 0;
        if (is_spike) {
          n0 = std::uniform_int_distribution<int>(0, P - 1)(rng);
          const double z = std::uniform_real_distribution<double>(5.0, 20.0)(rng);
          m(n0, ci) += (rng() % 2 ? 1.0 : -1.0) * z * sigma;
        } else {
          n0 = std::uniform_int_distribution<int>(P / 5, 4 * P / 5)(rng);
          const double a = std::uniform_real_distribution<double>(0.5, 1.5)(rng);
          m.block(n0, ci, P - n0, 1).array() += (rng() % 2 ? 1.0 : -1.0) * a;
        }
        const ResidualSpace space(c.cfg);
        // How many σ of it the residual can show: |size|·‖Π z‖ (a reading of configuration 4,
        // whose lever arm is 7 times the others', is nearly fitted by γ: ‖Π z‖ is small).
        const Eigen::VectorXd zc = stack_readings(m - c.m_um);
        const double shown =
            space.project_out(reduce_columns(c.cfg, Eigen::MatrixXd(zc))).norm() / sigma;
        GrossErrorScan g = find_gross_errors(space, m);
        const FourSensorResult before = separate_four_sensor(c.cfg, m, solve);
        const FourSensorResult after = separate_without_gross_errors(c.cfg, m, &g, before, solve);
        cell.add(before, after, c.S_um, g.found());
        bool ok = false, located = false;
        for (const auto& e : g.errors) {
          const bool here = is_spike ? e.position == n0 : std::abs(e.position - n0) <= 1;
          located =
              located || (e.kind == (is_spike ? GrossErrorKind::spike : GrossErrorKind::step) &&
                          (is_spike ? here && e.configuration == ci : here));
          if (&e == &g.errors.front())
            ok = e.applied && e.configuration == ci && here &&
                 e.kind == (is_spike ? GrossErrorKind::spike : GrossErrorKind::step);
          if (e.alternatives.size() > 1) {
            ++ambiguous;
            CHECK_FALSE(e.applied);
            CHECK(e.description.find("in one of the configurations") != std::string::npos);
            CHECK(e.description.find("cannot tell which") != std::string::npos);
            CHECK(e.description.find("widened by up to") != std::string::npos);
            bool holds = false;
            for (const auto& a : e.alternatives)
              holds = holds || (a.configuration == ci &&
                                (is_spike ? a.position == n0 : std::abs(a.position - n0) <= 1));
            ambiguous_holds_truth += holds ? 1 : 0;
          }
        }
        right += ok ? 1 : 0;
        if (shown >= kVisible) {
          ++visible;
          visible_right += ok ? 1 : 0;
          visible_located += located ? 1 : 0;
        }
        if (std::getenv("TRACE_DEBUG")) {
          std::printf("  dbg %s s%.2f seed %llu truth c%d n%d shown %.1f\n", kind, sigma,
                      static_cast<unsigned long long>(seed), ci + 1, n0, shown);
          for (const auto& f : g.findings)
            std::printf("      %s\n", f.c_str());
        }
      }
      char extra[200];
      std::snprintf(extra, sizeof extra,
                    "shown >= %.0f sigma %d: located %d, removed right %d (all runs %d); "
                    "ambiguous %d, truth among them %d",
                    kVisible, visible, visible_located, visible_right, right, ambiguous,
                    ambiguous_holds_truth);
      cell.print(kind, sigma, extra);
      points_all += cell.points;
      ambiguous_all += ambiguous;
      holds_all += ambiguous_holds_truth;
      covered_all += cell.covered_after;
      // Where the residual can show it: found at the right place in >= 80 %; a spike also
      // attributed and removed (a step's configuration is often ambiguous: see the file comment).
      CHECK(visible_located >= (8 * visible + 9) / 10);
      if (is_spike) CHECK(visible_right >= (8 * visible + 9) / 10);
      CHECK(cell.worse == 0);  // never worse by more than the stated u
    }
  }
  std::printf("ambiguous errors: the truth among the configurations named in %d of %d\n", holds_all,
              ambiguous_all);
  CHECK(holds_all * 10 >= 8 * ambiguous_all);
  const double cov = double(covered_all) / double(points_all);
  std::printf("coverage of u_S after the loop over the spike and step cells: %.3f (%ld points)\n",
              cov, points_all);
  CHECK(cov >= 0.90);
  CHECK(cov <= 0.99);
}

// A hysteresis of the sensor on a single scan (every configuration read forward): the reading
// lag test (the column −sign(dr/dx), signs at r̂ + h·z over a grid of h, residual_trace.cpp).
// Most of such a lag is absorbed by f, S and γ (it is what the profile read looks like); what
// the four configurations' different turns leave shows.  Random profiles, h 0.5-1.5 um (the
// generator's), 20 seeds per σ.  Asserted: found (the lag test significant at the trace's α,
// Bonferroni) in >= 80 % of the runs where the residual can show it (δ = ‖Π·Δm‖/σ >= 4.5, Δm the
// lag put into the readings: the non-linearity's criterion); on the same seeds' clean scans the
// lag test is significant in at most 5 %.  Measured: found 20, 20, 19 of 20 (δ >= 4.5 in all)
// at σ 0.05, 0.1, 0.2; clean 0 of 60.  With the signs at r̂ alone: 5, 5, 2 of 20 (the lag moves
// the fitted readings' turns, where the part that shows lies).
TEST_CASE(
    "a hysteresis on a single scan: the reading-lag test finds it where the residual shows it") {
  auto lag = [](const ResidualTrace& t) {
    for (const auto& d : t.tests)
      if (d.variable == "reading lag (hysteresis)") return d;
    return DependenceTest{};
  };
  int clean_runs = 0, clean_found = 0;
  for (double sigma : {0.05, 0.1, 0.2}) {
    int found = 0, showable = 0, found_showable = 0;
    constexpr int kSeeds = 20;
    for (std::uint64_t seed = 1; seed <= kSeeds; ++seed) {
      const UndeclaredCase c = clean_case(sigma, seed, UndeclaredEffect::hysteresis);
      const ResidualSpace space(c.cfg);
      const DependenceTest d = lag(trace_residual(space, c.m_um, {c.t_s, {}, {}}));
      REQUIRE(d.tested);
      const double delta =
          space.project_out(reduce_readings(c.cfg, c.m_um - c.m_clean_um)).norm() / sigma;
      found += d.significant;
      if (delta >= 4.5) {
        ++showable;
        found_showable += d.significant;
      }
      const DependenceTest dc = lag(trace_residual(space, c.m_clean_um, {c.t_s, {}, {}}));
      ++clean_runs;
      clean_found += dc.significant;
      if (d.significant) CHECK(d.finding.find("serpentine or reversed") != std::string::npos);
    }
    std::printf(
        "hysteresis on a single scan, sigma %.2f: reading lag found in %d of %d runs; the "
        "residual can show it (delta >= 4.5) in %d, found in %d of them\n",
        sigma, found, kSeeds, showable, found_showable);
    CHECK(found_showable >= 0.8 * showable);
  }
  std::printf("clean scans: reading lag found in %d of %d\n", clean_found, clean_runs);
  CHECK(clean_found <= 0.05 * clean_runs);
}

TEST_CASE("a residual that follows a recorded temperature is found, one that does not is not") {
  const UndeclaredCase c = clean_case(0.1, 77);
  const int P = c.cfg.positions();
  // A temperature record that wanders smoothly in time (period 63 s, two per traverse), and a
  // sensor that follows it at
  // 0.4 µm/K on configuration 2 only.
  Eigen::MatrixXd T(P, 4);
  for (int n = 0; n < P; ++n)
    for (int i = 0; i < 4; ++i)
      T(n, i) = 20.0 + 0.8 * std::sin(0.1 * c.t_s(n, i) + 0.4);
  Eigen::MatrixXd m = c.m_um;
  m.col(1) += 0.4 * (T.col(1).array() - 20.0).matrix();
  const ResidualSpace space(c.cfg);
  const ResidualTrace with = trace_residual(space, m, {c.t_s, {}, T});
  const ResidualTrace without = trace_residual(space, c.m_um, {c.t_s, {}, T});
  INFO(with.brief_report());
  const auto temp = std::find_if(with.tests.begin(), with.tests.end(), [](const DependenceTest& d) {
    return d.variable == "temperature";
  });
  REQUIRE(temp != with.tests.end());
  CHECK(temp->tested);
  INFO("temperature: F = " << temp->statistic << ", p = " << temp->p_value);
  CHECK(with.depends);
  CHECK_FALSE(without.depends);
  // Not recorded: said so, not tested.
  const ResidualTrace none = trace_residual(space, c.m_um, {c.t_s, {}, {}});
  for (const auto& d : none.tests)
    if (d.variable == "temperature" || d.variable == "direction") {
      CHECK_FALSE(d.tested);
      CHECK(d.not_tested == "not recorded");
    }
}

TEST_CASE("the refine reports a spike on its finding line and separates without it") {
  const UndeclaredCase c = clean_case(0.1, 4242);
  Eigen::MatrixXd m = c.m_um;
  const int n0 = c.cfg.positions() / 3;
  m(n0, 1) += 1.5;  // 15 σ on one reading of configuration 2
  RefineOptions o;
  o.residual.mc_samples = 199;
  const RefineTruth truth{c.f_um, c.S_um, c.gamma_rad};
  const RefineResult r = refine_four_sensor(c.cfg, m, c.t_s, o, &truth);
  const std::string line = r.brief_report();
  INFO(line);
  CHECK(line.find("spike: the reading of configuration 2") != std::string::npos);
  CHECK(line.find("removed from the separation") != std::string::npos);
  CHECK(r.gross_removed);
  CHECK_FALSE(r.model_complete());
  const double eb = S_error(r.before.S_um, c.S_um), ea = S_error(r.after.S_um, c.S_um);
  std::printf("refine with a 1.5 um spike: S error %.3f -> %.3f um (u_S rms %.3f)\n", eb, ea,
              rms(r.after.u_S_um));
  CHECK(ea < eb);
  if (std::getenv("TRACE_DEBUG")) std::printf("  %s\n", line.c_str());
  // Clean: nothing found, nothing said.
  const RefineResult rc = refine_four_sensor(c.cfg, c.m_um, c.t_s, o, &truth);
  CHECK_FALSE(rc.gross.found());
  CHECK(rc.brief_report().find("spike") == std::string::npos);
}

namespace {

// A reversed-plan sequence (each configuration forward, then back) with a knock: during a random
// traverse (of configuration `ci`) the sensor is offset by `a` from position n0 on in its
// direction of travel (a backward traverse: positions n <= n0), and it stays offset for every
// later traverse.  `in_first` says whether the knocked traverse is its configuration's first
// (the one the single scan uses).
struct KnockCase {
  FourSensorConfig cfg;
  ScanSequence seq;
  Eigen::MatrixXd M;  // P × T, the sequence's readings
  Eigen::MatrixXd m;  // P × 4, each configuration's first traverse (the single scan)
  Eigen::MatrixXd m_clean;
  Eigen::VectorXd S_um;
};

KnockCase knock_case(double sigma, std::uint64_t seed, bool knock, int* ci_out, int* n0_out,
                     bool* in_first = nullptr) {
  KnockCase k;
  const SlidewayTruth truth =
      random_smooth_truth(k.cfg, seed, UndeclaredCaseOptions::wavy_reference());
  k.seq = ScanSequence::make(ScanSequenceKind::reversed, k.cfg);
  SequenceSimOptions so;
  so.sigma_um = sigma;
  so.seed = seed;
  const SequenceSimData d = simulate_four_sensor_sequence(k.cfg, truth, k.seq, so);
  k.M = d.m_um;
  k.S_um = d.S_um;
  const int P = k.cfg.positions(), T = k.seq.size();
  std::mt19937_64 rng(seed * 7 + 3);
  const int K = std::uniform_int_distribution<int>(0, T - 1)(rng);
  const int ci = k.seq.traverses[static_cast<std::size_t>(K)].configuration;
  const bool backward =
      k.seq.traverses[static_cast<std::size_t>(K)].direction == TraverseDirection::backward;
  const int n0 = std::uniform_int_distribution<int>(P / 5, 4 * P / 5)(rng);
  const double a = (rng() % 2 ? 1.0 : -1.0) * std::uniform_real_distribution<double>(0.5, 1.5)(rng);
  std::array<int, 4> first{-1, -1, -1, -1};
  for (int t = 0; t < T; ++t) {
    const int c = k.seq.traverses[static_cast<std::size_t>(t)].configuration;
    if (first[static_cast<std::size_t>(c)] < 0) first[static_cast<std::size_t>(c)] = t;
  }
  k.m.resize(P, 4);
  k.m_clean.resize(P, 4);
  for (int c = 0; c < 4; ++c)
    k.m_clean.col(c) = k.M.col(first[static_cast<std::size_t>(c)]);
  if (knock) {
    if (backward)
      k.M.block(0, K, n0 + 1, 1).array() += a;
    else
      k.M.block(n0, K, P - n0, 1).array() += a;
    for (int t = K + 1; t < T; ++t)
      k.M.col(t).array() += a;
  }
  for (int c = 0; c < 4; ++c)
    k.m.col(c) = k.M.col(first[static_cast<std::size_t>(c)]);
  if (ci_out) *ci_out = ci;
  if (n0_out) *n0_out = backward ? n0 + 1 : n0;  // the first position the two traverses differ
  if (in_first) *in_first = K == first[static_cast<std::size_t>(ci)];
  return k;
}

}  // namespace

TEST_CASE("a knocked sensor: measuring each configuration twice names its configuration",
          "[sweep]") {
  constexpr int kSeeds = 20;
  const FourSensorOptions solve;
  // Calibration: clean reversed-plan sequences, alpha = 0.05.
  {
    RepeatStepOptions o;
    o.alpha = 0.05;
    int runs = 0, alarms = 0;
    for (double sigma : {0.05, 0.1, 0.2})
      for (std::uint64_t s = 1; s <= 40; ++s) {
        const KnockCase k = knock_case(sigma, 3000 + s, false, nullptr, nullptr);
        alarms += find_repeat_steps(k.cfg, k.seq, k.M, o).found ? 1 : 0;
        ++runs;
      }
    const double bound = 0.05 + 2.0 * std::sqrt(0.05 * 0.95 / runs);
    std::printf(
        "repeat-step search on %d clean reversed-plan scans at alpha 0.05: %d alarms "
        "(%.3f, bound %.3f)\n",
        runs, alarms, double(alarms) / runs, bound);
    CHECK(double(alarms) / runs <= bound);
  }
  std::printf("knock 0.5-1.5 um during one traverse of a reversed plan\n");
  print_header();
  for (double sigma : {0.05, 0.1, 0.2}) {
    Cell alone, with;
    int named = 0, single_right = 0, repeat_right = 0, clean_alarms = 0, firsts = 0;
    for (int s = 1; s <= kSeeds; ++s) {
      int ci = 0, n0 = 0;
      bool in_first = false;
      const KnockCase k =
          knock_case(sigma, 900 + static_cast<std::uint64_t>(s), true, &ci, &n0, &in_first);
      firsts += in_first ? 1 : 0;
      const ResidualSpace space(k.cfg);
      const RepeatStepScan rs = find_repeat_steps(k.cfg, k.seq, k.M);
      const bool right =
          rs.found && rs.attributed && rs.configuration == ci && std::abs(rs.position - n0) <= 1;
      named += right ? 1 : 0;
      const FourSensorResult before = separate_four_sensor(k.cfg, k.m, solve);
      // The single scan alone (its first traverses), then with the repeat's attribution.
      GrossErrorScan g0 = find_gross_errors(space, k.m);
      const FourSensorResult a0 = separate_without_gross_errors(k.cfg, k.m, &g0, before, solve);
      GrossErrorOptions go;
      if (rs.found && rs.attributed)
        go.attributed_steps.push_back({rs.configuration, rs.position, rs.size_um, rs.u_size_um,
                                       "the configuration's two traverses"});
      GrossErrorScan g1 = find_gross_errors(space, k.m, go);
      const FourSensorResult a1 = separate_without_gross_errors(k.cfg, k.m, &g1, before, solve);
      alone.add(before, a0, k.S_um, g0.found());
      with.add(before, a1, k.S_um, g1.found() || rs.found);
      if (S_error(a1.S_um, k.S_um) > S_error(before.S_um, k.S_um) + rms(a1.u_S_um)) {
        std::printf("    worse: knock sigma %.2f seed %d (configuration %d, first traverse %d):\n",
                    sigma, 900 + s, ci + 1, in_first ? 1 : 0);
        for (const auto& f : g1.findings)
          std::printf("      %s\n", f.c_str());
      }
      auto removed_right = [&](const GrossErrorScan& g) {
        for (const auto& e : g.errors)
          if (e.applied && e.kind == GrossErrorKind::step && e.configuration == ci &&
              std::abs(e.position - n0) <= 1)
            return true;
        return false;
      };
      single_right += in_first && removed_right(g0) ? 1 : 0;
      repeat_right += in_first && removed_right(g1) ? 1 : 0;
      const KnockCase c =
          knock_case(sigma, 900 + static_cast<std::uint64_t>(s), false, nullptr, nullptr);
      clean_alarms += find_repeat_steps(c.cfg, c.seq, c.M).found ? 1 : 0;
      if (std::getenv("TRACE_DEBUG")) {
        std::printf("  dbg knock s%.2f seed %d truth c%d n%d first %d: S %.3f -> %.3f / %.3f: %s\n",
                    sigma, 900 + s, ci + 1, n0, in_first ? 1 : 0, S_error(before.S_um, k.S_um),
                    S_error(a0.S_um, k.S_um), S_error(a1.S_um, k.S_um), rs.finding.c_str());
        for (const auto& f : g1.findings)
          std::printf("      %s\n", f.c_str());
      }
    }
    char extra[200];
    std::snprintf(extra, sizeof extra,
                  "knock in a first traverse (what the single scan holds) %d; removed at the "
                  "right place %d",
                  firsts, single_right);
    alone.print("knock: 1 scan", sigma, extra);
    std::snprintf(extra, sizeof extra,
                  "repeats name the configuration %d/%d (clean alarms %d/%d); removed right %d",
                  named, kSeeds, clean_alarms, kSeeds, repeat_right);
    with.print("+ repeats", sigma, extra);
    CHECK(clean_alarms <= kSeeds / 20);
    CHECK(named * 10 >= 8 * kSeeds);
    CHECK(with.worse == 0);
    CHECK(alone.worse == 0);
  }
}

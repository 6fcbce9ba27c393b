// Closing the loop for the two-axis displacement method (issue 16 item 4): random stages, noise
// on every reading, one undeclared effect per cell (displacement_effects.hpp) at a size that at
// least doubles the clean error, four scan plans (scan 2 as scan 1, the paper's; scan 2
// backwards; scan 2 y fastest and backwards, the plan where drift shows; and that with scan 1
// along diagonals, the plan where thermal drift shows, in a test case of its own).
// Per cell: taken (any effect significant), ident (the injected effect's family taken), appl
// (a correction applied), error of w and m_w (shape: constant removed) before and after (median,
// worst), halved (w error at most half), worse (w error grown by more than the refined u's RMS),
// coverage of the refined u_w (points within 2u against the truth in the method's gauge).
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "errsep/core/displacement_refine.hpp"
#include "errsep/core/displacement_simulation.hpp"
#include "support/displacement_cases.hpp"

using namespace errsep::core;
using errsep::test::random_two_axis_truth;

namespace {

constexpr int kSeeds = 20;
constexpr int kN = 25;
constexpr double kStepMm = 5.0;
constexpr double kPauseS = 60.0;

enum class Effect { none, thermal, tilt, drift };
const char* name(Effect e) {
  switch (e) {
    case Effect::none:
      return "clean";
    case Effect::thermal:
      return "thermal";
    case Effect::tilt:
      return "tilt";
    case Effect::drift:
      return "drift";
  }
  return "?";
}

double sign_size(std::mt19937_64& rng, double size) {
  std::uniform_real_distribution<double> u(0.5, 1.0);
  return (rng() % 2 ? 1.0 : -1.0) * size * u(rng);
}

/// A disturbance of random size and sign per sensor, scaled with σ so that it at least doubles
/// the clean error of w at every noise level (checked below).
DisplacementDisturbance random_disturbance(Effect e, double sigma, std::uint64_t seed) {
  std::mt19937_64 rng(seed * 31 + 7);
  DisplacementDisturbance d;
  const double scan_s = kN * kN * 1.0;
  switch (e) {
    case Effect::none:
      break;
    case Effect::thermal:
      for (auto& a : d.thermal_um)
        a = sign_size(rng, 3.0 * sigma);
      d.thermal_tau_s = scan_s * std::exp(std::uniform_real_distribution<double>(
                                     std::log(0.3), std::log(3.0))(rng));
      break;
    case Effect::tilt:
      d.tilt_x_urad = sign_size(rng, 50.0 * sigma);
      d.tilt_y_urad = sign_size(rng, 50.0 * sigma);
      break;
    case Effect::drift:
      for (auto& v : d.drift_um_per_s)
        v = sign_size(rng, 0.002 * sigma);
      break;
  }
  return d;
}

double rms(const Eigen::MatrixXd& e) {
  return std::sqrt((e.array() - e.mean()).square().mean());
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

struct CellStats {
  int runs = 0, taken = 0, applied = 0, halved = 0, worse = 0, identified = 0;
  /// Runs whose refine says two effects are not separable on the plan; runs with both taken.
  int confounded = 0, both_taken = 0;
  /// Runs that took a tilt or a drift (not both) on a plan where both are identifiable and did
  /// not say that the other explains the same residual.
  int unsaid = 0;
  /// Runs whose fit predicts the w error halved by what was decided, and of those halved.
  int predicted = 0, predicted_halved = 0;
  /// Over the applied runs' points: the refined u over the clean readings' separation's u, and
  /// over the separation's u of the readings as measured (smallest).
  double u_ratio_min = 1e300, u_base_ratio_min = 1e300;
  std::vector<double> w_before, w_after, m_before, m_after;
  long covered = 0, points = 0;
  /// Over the runs where an effect was detected and not (or not wholly) applied.
  long covered_na = 0, points_na = 0;
};

struct Plan {
  TwoAxisScanOrder order;
  DisplacementEffectLibrary lib;
  /// A short column label.
  std::string label() const {
    const std::string d = order.diagonal_scan1 ? "diag+" : "";
    if (order.y_fastest_scan2) return d + (order.reverse_scan2 ? "y-fast-bw" : "y-fast");
    return d + (order.reverse_scan2 ? "backward" : order.diagonal_scan1 ? "x-fast" : "paper");
  }
};

CellStats run_cell(const Plan& plan, Effect effect, double sigma,
                   const DisplacementRefineOptions& ro) {
  CellStats c;
  for (int s = 0; s < kSeeds; ++s) {
    const std::uint64_t seed =
        5000 + static_cast<std::uint64_t>(s) + 100 * static_cast<std::uint64_t>(effect) +
        static_cast<std::uint64_t>(1000 * sigma) * 13 + (plan.order.reverse_scan2 ? 50000 : 0) +
        (plan.order.y_fastest_scan2 ? 70000 : 0) + (plan.order.diagonal_scan1 ? 90000 : 0);
    TwoAxisSimOptions so;
    so.nx = so.ny = kN;
    so.eddy_sensor.noise_sigma_um = sigma;
    so.contact_sensor.noise_sigma_um = 1.8 * sigma;  // the paper's 0.29 / 0.16
    so.record_s0_scan2 = true;
    so.timing.sample_period_s = 1.0;
    so.timing.pause_between_scans_s = kPauseS;
    so.reverse_scan2 = plan.order.reverse_scan2;
    so.y_fastest_scan2 = plan.order.y_fastest_scan2;
    so.diagonal_scan1 = plan.order.diagonal_scan1;
    so.disturbance = random_disturbance(effect, sigma, seed);
    so.seed = seed;
    const auto truth = random_two_axis_truth(seed, 0.0);
    const auto sim = simulate_two_axis(truth, so);
    TwoAxisOptions o;
    o.rotation = RotationCorrection::off;
    const auto r = refine_two_axis(sim.scan, o, plan.lib, ro);
    // The method's gauge: r2_x(x_0) = r4_y(y_0) = 0 (rotation off).
    const double g = truth.r2x_um(sim.scan.x_mm(0)) + truth.r4y_um(sim.scan.y_mm(0));
    const Eigen::MatrixXd wt = sim.w_um.array() - g, mt = sim.m_w_um.array() + g;
    const double wb = rms(r.base.w_um - wt), wa = rms(r.refined.w_um - wt);
    c.w_before.push_back(wb);
    c.w_after.push_back(wa);
    c.m_before.push_back(rms(r.base.m_w_um - mt));
    c.m_after.push_back(rms(r.refined.m_w_um - mt));
    ++c.runs;
    bool taken = false, identified = false;
    for (const auto& st : r.steps) {
      taken = true;
      identified = identified || st.effect.rfind(name(effect), 0) == 0;
    }
    c.taken += taken;
    bool said = false, tilt = false, drift = false;
    for (const auto& n : r.not_identifiable)
      said = said || n.find("not separable on this plan") != std::string::npos;
    for (const auto& st : r.steps) {
      tilt = tilt || st.effect.rfind("tilt", 0) == 0;
      drift = drift || st.effect.rfind("drift", 0) == 0;
    }
    c.confounded += said;
    c.both_taken += tilt && drift;
    // Scan 1 along diagonals makes the offset between sensor 0's two readings not affine in the
    // grid indices (the wrap), so sensor 0's drift is no longer a tilt's direction there.
    c.unsaid += plan.order.plan_name() != TwoAxisScanOrder{}.plan_name() &&
                !plan.order.diagonal_scan1 && tilt != drift && !said;
    c.identified += identified && effect != Effect::none;
    c.applied += r.applied_any();
    c.halved += wa <= 0.5 * wb;
    {
      // Predicted from the fit (never the truth): the w error without the effect's correction
      // (the separation's u and every group's estimated bias) and with what was decided (the
      // applied groups' covariance, the left-out groups' bias).  Printed, not used to say where
      // an effect is identifiable: it is optimistic for thermal drift and for a drift scanned
      // backwards x fastest (τ's non-linearity; sensors 3-4 fitted to a few σ of their u).
      double floor2 = 0, before2 = 0, after2 = 0;
      for (const auto& st : r.steps) {
        const auto* q = st.decision.quantity("w");
        if (!q) continue;
        floor2 = q->rms_u_base * q->rms_u_base;
        before2 += q->rms_bias * q->rms_bias;
        after2 += st.applied ? q->rms_added_u * q->rms_added_u : q->rms_bias * q->rms_bias;
      }
      const bool predicted = !r.steps.empty() && floor2 + after2 <= 0.25 * (floor2 + before2);
      c.predicted += predicted;
      c.predicted_halved += predicted && wa <= 0.5 * wb;
    }
    const double u_rms = std::sqrt(r.refined.u_w_um.array().square().mean());
    if (wa > wb + u_rms) {
      ++c.worse;
      std::printf("  worse: %s sigma %.2f seed %llu: %.3f -> %.3f um (u %.3f)\n%s", name(effect),
                  sigma, static_cast<unsigned long long>(seed), wb, wa, u_rms,
                  r.brief_report().c_str());
    }
    if (r.applied_any()) {
      // The refined u against what the separation states for the same readings without the
      // effect (the truth removed): the corrected readings' σ̂ drops, but the refined u must
      // not claim more than the clean data give.
      TwoAxisScan clean = sim.scan;
      DisplacementDisturbance minus = so.disturbance;
      for (auto& a : minus.thermal_um)
        a = -a;
      for (auto& v : minus.drift_um_per_s)
        v = -v;
      minus.tilt_x_urad = -minus.tilt_x_urad;
      minus.tilt_y_urad = -minus.tilt_y_urad;
      add_disturbance(clean, minus, plan.order);
      const auto sep = separate_two_axis(clean, o);
      const Eigen::ArrayXXd ratio = r.refined.u_w_um.array() / sep.u_w_um.array();
      const Eigen::ArrayXXd ratio_base = r.refined.u_w_um.array() / r.base.u_w_um.array();
      for (Eigen::Index k = 0; k < ratio.size(); ++k)
        if (sep.u_w_um(k) > 0) {
          c.u_ratio_min = std::min(c.u_ratio_min, ratio(k));
          c.u_base_ratio_min = std::min(c.u_base_ratio_min, ratio_base(k));
        }
    }
    const Eigen::ArrayXXd err = (r.refined.w_um - wt).array().abs();
    c.covered += (err <= 2.0 * r.refined.u_w_um.array()).count();
    c.points += err.size();
    bool left_out = false;
    for (const auto& st : r.steps)
      left_out = left_out || !st.applied;
    if (left_out) {
      c.covered_na += (err <= 2.0 * r.refined.u_w_um.array()).count();
      c.points_na += err.size();
    }
  }
  return c;
}

Plan make_plan(bool reverse, bool y_fastest = false, bool diagonal = false) {
  Plan p;
  p.order = TwoAxisScanOrder{1.0, kPauseS, reverse, y_fastest, diagonal};
  const Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(kN, 0.0, (kN - 1) * kStepMm);
  TwoAxisOptions o;
  p.lib = make_displacement_effect_library(x, x, true, p.order, o);
  return p;
}

}  // namespace

TEST_CASE("scan 1 along diagonals reads every point once and every row and column over scan 1") {
  for (const auto& [nx, ny] : {std::pair{25, 25}, std::pair{7, 4}, std::pair{4, 9}}) {
    TwoAxisScanOrder o;
    o.diagonal_scan1 = true;
    std::vector<int> seen(static_cast<std::size_t>(nx * ny), 0);
    std::vector<double> row_lo(nx, 1e300), row_hi(nx, -1), col_lo(ny, 1e300), col_hi(ny, -1);
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const double t = o.time_s(1, i, j, nx, ny);
        REQUIRE(t >= 0);
        REQUIRE(t < nx * ny);
        ++seen[static_cast<std::size_t>(t)];
        row_lo[i] = std::min(row_lo[i], t);
        row_hi[i] = std::max(row_hi[i], t);
        col_lo[j] = std::min(col_lo[j], t);
        col_hi[j] = std::max(col_hi[j], t);
      }
    CHECK(std::count(seen.begin(), seen.end(), 1) == nx * ny);
    // A raster x fastest reads a column within nx samples; along diagonals each row and column
    // spans at least (n_other - 1) of its reading's steps of nx samples.
    for (int i = 0; i < nx; ++i)
      CHECK(row_hi[i] - row_lo[i] >= (ny - 1) * nx);
    for (int j = 0; j < ny; ++j)
      CHECK(col_hi[j] - col_lo[j] >= (std::min(nx, ny) - 1) * nx - nx);
    // Scan 2 is unchanged by it.
    TwoAxisScanOrder r;
    CHECK(o.time_s(2, 1, 2, nx, ny) == r.time_s(2, 1, 2, nx, ny));
  }
}

TEST_CASE("which effects each scan plan can identify, computed without data") {
  const Plan same = make_plan(false), rev = make_plan(true), yf = make_plan(false, true),
             yfr = make_plan(true, true), dg = make_plan(true, true, true);
  auto identifiable = [](const Plan& p, const std::string& family) {
    bool any = false;
    for (const auto& e : p.lib.effects)
      if (e.family == family) any = any || e.identifiable;
    return any;
  };
  for (const Plan* p : {&same, &rev, &yf, &yfr, &dg}) {
    std::printf(
        "plan %s:   u of the fitted correction on w per um of noise: sensor 0 | 1-2 | 3-4\n",
        p->order.plan_name().c_str());
    for (const auto& e : p->lib.effects) {
      std::printf("  %-24s identifiable %d (relative singular value %.2e)", e.name.c_str(),
                  e.identifiable, e.relative_singular_value);
      for (const double u : e.group_u_w_per_sigma)
        std::printf(" %7.3f", u);
      std::printf("\n");
    }
    for (const auto& n : p->lib.not_identifiable)
      std::printf("  %s\n", n.c_str());
  }
  CHECK_FALSE(identifiable(same, "drift"));
  for (const Plan* p : {&rev, &yf, &yfr}) {
    CHECK(identifiable(*p, "drift"));
    CHECK(identifiable(*p, "thermal"));
    CHECK(identifiable(*p, "tilt"));
  }
  CHECK(identifiable(same, "thermal"));
  CHECK(identifiable(same, "tilt"));
  // Identifiable, but the pair of sensors whose column scan 1 reads within n_x samples (3-4) is
  // poorly determined on a raster scan 1: said, with the diagonal plan as the remedy; on the
  // diagonal plan (3-4 determined as well as 1-2, table above) nothing is said.
  auto says = [](const Plan& p, const std::string& start) {
    for (const auto& n : p.lib.not_identifiable)
      if (n.rfind(start, 0) == 0) return true;
    return false;
  };
  for (const Plan* p : {&same, &rev, &yf, &yfr}) {
    CHECK(says(*p, "thermal of sensors 3-4: poorly determined on this plan"));
    CHECK_FALSE(says(*p, "thermal of sensors 1-2: poorly determined"));
  }
  CHECK(says(rev, "drift of sensors 3-4: poorly determined on this plan"));
  CHECK_FALSE(says(yfr, "drift of sensors 3-4: poorly determined"));
  for (const auto& n : dg.lib.not_identifiable)
    CHECK(n.find("poorly determined") == std::string::npos);
  // Without sensor 0's repeat nothing sees a tilt between the scans.
  const Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(kN, 0.0, (kN - 1) * kStepMm);
  const auto lib = make_displacement_effect_library(x, x, false, TwoAxisScanOrder{1.0, kPauseS},
                                                    TwoAxisOptions{});
  bool tilt = false;
  for (const auto& e : lib.effects)
    tilt = tilt || (e.family == "tilt" && e.identifiable);
  CHECK_FALSE(tilt);
}

namespace {

/// The table over these plans (the assertions per cell and on the pooled coverage).
void run_table(const std::vector<Plan>& plans) {
  // The loop's own decision rule (bias_z = 0).  bias_z = 2 (the four-sensor loop's,
  // refine_step_decision) was measured here on every cell: it kept worse at 0 and raised the
  // coverage 0.961 -> 0.966, but cut the halvings of the cells asserted below (drift scanned y
  // fastest backwards 18/18/17 -> 7/4/6 of 20, thermal drift with scan 1 diagonal 17/19/19 ->
  // 11/12/11) and left drift scanned backwards x fastest at 0/20: not taken.
  const DisplacementRefineOptions ro;
  std::printf(
      "25 x 25 grid, 5 mm, sensor 0 at 1.8 sigma and read in both scans, rotation off; w and m_w "
      "errors RMS after the constant, um\n"
      "%-7s %-9s %-8s %5s %5s %5s  %-24s %-24s %6s %6s %6s %s\n",
      "sigma", "plan", "effect", "taken", "ident", "appl", "w before->after med (worst)",
      "m_w before->after med", "halved", "worse", "cover",
      "cover where detected, not applied (runs)");
  long cov_in = 0, pts_in = 0, cov_na = 0, pts_na = 0;
  int not_met = 0;
  for (const double sigma : {0.05, 0.1, 0.2}) {
    std::vector<double> clean_median(plans.size(), 0.0);
    for (std::size_t pi = 0; pi < plans.size(); ++pi) {
      const Plan& plan = plans[pi];
      for (const Effect e : {Effect::none, Effect::thermal, Effect::tilt, Effect::drift}) {
        const CellStats c = run_cell(plan, e, sigma, ro);
        const double wb = median(c.w_before), wa = median(c.w_after);
        const double wworst_b = *std::max_element(c.w_before.begin(), c.w_before.end());
        const double wworst_a = *std::max_element(c.w_after.begin(), c.w_after.end());
        std::printf(
            "%-7.2f %-9s %-8s %2d/%-2d %2d/%-2d %2d/%-2d  %5.3f->%5.3f (%5.2f->%5.2f)  "
            "%5.3f->%5.3f     %3d/%-2d %2d/%-2d %6.3f %6.3f (%ld)\n",
            sigma, plan.label().c_str(), name(e), c.taken, c.runs, c.identified, c.runs, c.applied,
            c.runs, wb, wa, wworst_b, wworst_a, median(c.m_before), median(c.m_after), c.halved,
            c.runs, c.worse, c.runs, static_cast<double>(c.covered) / c.points,
            c.points_na ? static_cast<double>(c.covered_na) / c.points_na : 1.0,
            c.points_na / (kN * kN));
        if (c.applied)
          std::printf(
              "        refined u over the clean readings' separation's u >= %.3f, over the "
              "measured readings' >= %.3f (smallest point)\n",
              c.u_ratio_min, c.u_base_ratio_min);
        // The refined u never claims more than the clean readings give: the corrected readings'
        // σ̂ differs from the clean ones' only by what the ≤ 11 fitted parameters' error leaves
        // in ~2400 residual degrees of freedom (χ²₁₁ at 1e-4 is 35: ≤ 1.5 % of the sum of
        // squares, 0.7 % of σ̂), and the applied parameters' covariance only adds.
        if (c.applied) CHECK(c.u_ratio_min >= 0.99);
        if (e != Effect::none)
          std::printf(
              "        halving predicted from the fit in %d/%d runs, halved in %d of them\n",
              c.predicted, c.runs, c.predicted_halved);
        if (c.confounded || c.both_taken)
          std::printf(
              "        two effects not separable on this plan, said in %d/%d runs (both "
              "taken in %d)\n",
              c.confounded, c.runs, c.both_taken);
        const bool identifiable =
            e != Effect::none &&
            !(e == Effect::drift && plan.order.plan_name() == TwoAxisScanOrder{}.plan_name());
        if (e == Effect::none) {
          clean_median[pi] = wb;
          // Clean runs add nothing in <= 5 %.
          CHECK(c.applied <= 0.05 * c.runs);
        } else {
          // Each effect at least doubles the clean error (else the cell tests nothing).
          CHECK(wb >= 2.0 * clean_median[pi]);
        }
        // On every plan but the paper's, sensor 0's drift is affine in the grid indices (its two
        // readings' time offset is), i.e. one direction of a tilt: whichever is taken, the
        // other explanation is said and carried in u.
        CHECK(c.unsaid == 0);
        // A correction never makes w worse by more than its stated u.
        CHECK(c.worse == 0);
        // The plan made for drift (scan 2 y fastest, backwards): every sensor's drift shows along
        // rows and columns alike (the identifiability table above), so it is asserted there.
        // The plan made for thermal drift (scan 1 along diagonals, scan 2 y fastest backwards):
        // every row and column is read over the whole of scan 1, so sensors 3-4's thermal drift
        // is determined as well as 1-2's (0.33-1.07 per um of noise over the tau grid, against
        // 1.6-5.0 with scan 1 a raster): asserted there.
        const bool drift_plan = plan.order.y_fastest_scan2 && plan.order.reverse_scan2;
        const bool thermal_plan = drift_plan && plan.order.diagonal_scan1;
        if (e == Effect::tilt || (e == Effect::drift && drift_plan) ||
            (e == Effect::thermal && thermal_plan)) {
          CHECK(c.halved >= 0.8 * c.runs);
        } else if (identifiable && c.halved < 0.8 * c.runs) {
          // Issue 16 asks for >= 80 %: not met for thermal drift with scan 1 a raster, nor for
          // linear drift scanned backwards x fastest (printed, not asserted).  Backwards, the
          // reference Y sensors 3-4 compare readings along the raster's fast axis and see only the
          // fast part of their drift (u of the correction on w ~20 per um of noise, against ~1.5
          // y fastest).  With scan 1 a raster x fastest, a column (what sensors 3-4 compare) is
          // read within n_x samples, so their thermal drift shows only through scan 2, when a
          // drift with tau below about a scan has settled: its correction's u on w is 1.6-5.0 per
          // um of noise while the drift moves w by ~5x the clean error.
          std::printf("        NOT MET: halved in %d/%d (issue 16 asks >= 80 %%)\n", c.halved,
                      c.runs);
          ++not_met;
        } else if (!identifiable && e == Effect::drift) {
          // Not identifiable from this plan: nothing applied for it (said once by the library).
          CHECK(c.identified == 0);
        }
        cov_na += c.covered_na;
        pts_na += c.points_na;
        if (c.points_na && c.covered_na < 0.9 * c.points_na)
          std::printf("        below 0.90 where detected and not applied: %.3f over %ld run(s)\n",
                      static_cast<double>(c.covered_na) / c.points_na, c.points_na / (kN * kN));
        if (identifiable || e == Effect::none) {
          cov_in += c.covered;
          pts_in += c.points;
        }
      }
    }
  }
  std::printf("cells below the issue's 80 %% halving: %d (drift and thermal; see above)\n",
              not_met);
  const double cover = static_cast<double>(cov_in) / pts_in;
  std::printf("coverage of the refined u_w (2u), clean and identifiable cells: %.3f\n", cover);
  CHECK(cover >= 0.90);
  CHECK(cover <= 0.99);
  // Where an effect was detected and (in part) not applied, its fitted size and that size's
  // scatter widen u (displacement_refine.cpp): pooled over those runs.
  const double cover_na = static_cast<double>(cov_na) / pts_na;
  std::printf(
      "coverage of the refined u_w (2u) where an effect was detected and not applied: "
      "%.3f over %ld runs\n",
      cover_na, pts_na / (kN * kN));
  CHECK(cover_na >= 0.90);
  CHECK(cover_na <= 0.99);
}

}  // namespace

TEST_CASE("displacement refine: the closing-the-loop table, sigma 0.05/0.1/0.2 um, 20 seeds",
          "[sweep]") {
  run_table({make_plan(false), make_plan(true), make_plan(true, true)});
}

TEST_CASE("displacement refine: the closing-the-loop table on scan 1 diagonal, 20 seeds",
          "[sweep]") {
  run_table({make_plan(true, true, true)});
}

// Are the stated uncertainties of the refinement's parameters right?  Over many noise seeds at
// the paper's noise levels (Zhao 2019 section 3: sigma = 0.1, 0.2, 0.3 um), the error of every
// determined combination w'p of the added effect's parameters, divided by its stated standard
// uncertainty sqrt(w'Cw), must be within 1 in about 68 % and within 2 in about 95 % of cases.
//
// Each effect is injected as the physics makes it, not through the effect's own correction:
// PE1 and the periodic positioning error through the simulator (actual spacings, the slide at
// x + dx(x)), the gain as m_3 -> 1.05 m_3; Example 2's reference surface (Eq. 24, k = 3) for all.
// Only runs in which the loop added that effect alone count (selection by the F-test would bias
// the others); the sizes are chosen so that this is nearly every run, which at sigma = 0.3 um
// they are not (added in about two thirds of the runs), so the runs are at 0.1 and 0.2 um.
//
// Bands.  The z of one run's directions are correlated (one noise draw), so the effective sample
// is the number of runs, not of directions: with R runs the 1-u fraction has a sampling standard
// deviation of sqrt(0.68*0.32/R) and the 2-u fraction sqrt(0.95*0.05/R).  Pooled over all
// effects the fractions must be within 2 of those standard deviations of 0.68 and 0.95 (2u: at
// most 1.0); each effect on its own within 3.
//
// What is known not to pass, and why it is not here: PE1 at sigma >= 0.2 um.  Its dD4 is then
// determined to +-1.3 mm on a reference surface whose shortest component has a 34 mm period, the
// least-squares surface has a second minimum at dD4 of 8-12 mm in some seeds (the same minimum from
// a start at the truth), and the z spread is 1.5-1.7 instead of 1 (measured over 100 seeds with
// fit_effects started at the truth; sigma = 0.1: 1.02-1.07).
#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>
#include <vector>

#include "errsep/core/effect_periodic.hpp"
#include "errsep/core/refine.hpp"
#include "support/refine_cases.hpp"

using namespace errsep::core;
using errsep::test::make_refine_case;

namespace {

struct Coverage {
  int runs = 0, counted = 0;
  std::vector<double> z;
  double within(double k) const {
    if (z.empty()) return 0.0;
    return static_cast<double>(
               std::count_if(z.begin(), z.end(), [k](double v) { return std::abs(v) <= k; })) /
           static_cast<double>(z.size());
  }
  void add(const Coverage& o) {
    runs += o.runs;
    counted += o.counted;
    z.insert(z.end(), o.z.begin(), o.z.end());
  }
};

// Runs the loop on `seeds` scans per sigma and collects the z of the effect's determined
// combinations.  `p_true` may depend on the chosen variant (the periodic error's grid period).
template <class MakeCase, class Truth>
Coverage collect(const std::string& effect, const std::vector<double>& sigmas, int seeds,
                 MakeCase make_case, Truth p_true) {
  Coverage c;
  RefineOptions o;
  o.residual.mc_samples = 119;  // the whiteness test is not what is measured here
  for (double sigma : sigmas)
    for (int seed = 1; seed <= seeds; ++seed) {
      const auto rc = make_case(sigma, static_cast<std::uint64_t>(7000 + seed));
      const auto r = refine_four_sensor(rc.cfg, rc.sim.m_um, Eigen::MatrixXd(), o);
      ++c.runs;
      if (r.effects.size() != 1 || r.effects.front()->name() != effect) continue;
      ++c.counted;
      const RefineStep& s = r.steps[1];
      for (double z : errsep::test::standardised_errors(s.identifiable_directions, s.covariance,
                                                        s.parameters, p_true(*r.effects.front())))
        c.z.push_back(z);
    }
  return c;
}

void report_and_check(const char* what, const Coverage& c, double n_sd) {
  const double w1 = c.within(1.0), w2 = c.within(2.0);
  const double sd1 = std::sqrt(0.68 * 0.32 / c.counted), sd2 = std::sqrt(0.95 * 0.05 / c.counted);
  std::printf(
      "%s: effect added alone in %d of %d runs, %zu directions: within 1 u %.3f, within 2 u "
      "%.3f (bands %.3f-%.3f and %.3f-1)\n",
      what, c.counted, c.runs, c.z.size(), w1, w2, 0.68 - n_sd * sd1, 0.68 + n_sd * sd1,
      0.95 - n_sd * sd2);
  CHECK(c.counted >= c.runs * 9 / 10);
  CHECK(w1 >= 0.68 - n_sd * sd1);
  CHECK(w1 <= 0.68 + n_sd * sd1);
  CHECK(w2 >= 0.95 - n_sd * sd2);
}

constexpr int kSeeds = 20;

Coverage gain_coverage() {
  const Eigen::Vector3d g(0.0, 0.05, 0.0);
  return collect(
      "gain", {0.1, 0.2}, kSeeds,
      [&](double sigma, std::uint64_t seed) {
        return make_refine_case(
            sigma, seed, {},
            [&](Eigen::MatrixXd& m, const Eigen::MatrixXd&) { m.col(2) *= 1.0 + g(1); }, 3);
      },
      [&](const ModelEffect&) { return Eigen::VectorXd(g); });
}

Coverage periodic_coverage() {
  const double A = 600.0, pitch = 23.0, phase = 0.3;
  return collect(
      "periodic", {0.1, 0.2}, kSeeds,
      [&](double sigma, std::uint64_t seed) {
        return make_refine_case(
            sigma, seed,
            [&](FourSensorSimOptions& so) {
              so.positioning_error_um = [=](double x) {
                return A * std::sin(2.0 * std::numbers::pi * x / pitch + phase);
              };
            },
            {}, 3);
      },
      [&](const ModelEffect& e) {
        const auto& per = dynamic_cast<const PeriodicEffect&>(e);
        return Eigen::VectorXd(
            Eigen::Vector3d(A * std::sin(phase), A * std::cos(phase), pitch - per.period_mm()));
      });
}

Coverage pe1_coverage() {
  const Eigen::Vector3d dD(0.8, -0.6, 0.6);
  return collect(
      "pe1", {0.1}, 2 * kSeeds,
      [&](double sigma, std::uint64_t seed) {
        return make_refine_case(
            sigma, seed,
            [&](FourSensorSimOptions& so) {
              so.actual_spacing_mm = std::array<double, 3>{5.0 + dD(0), 5.0 + dD(1), 25.0 + dD(2)};
            },
            {}, 3);
      },
      [&](const ModelEffect&) { return Eigen::VectorXd(dD); });
}

}  // namespace

TEST_CASE("coverage: stated uncertainties of gain, periodic error and PE1 at sigma 0.1-0.2 um",
          "[sweep]") {
  const Coverage g = gain_coverage(), p = periodic_coverage(), e = pe1_coverage();
  report_and_check("gain 5 % of configuration 3, sigma 0.1 and 0.2 um", g, 3.0);
  report_and_check("periodic 600 um / 23 mm, sigma 0.1 and 0.2 um", p, 3.0);
  report_and_check("PE1 (0.8, -0.6, 0.6) mm, Example 2 (k = 3), sigma 0.1 um", e, 3.0);
  Coverage all;
  all.add(g);
  all.add(p);
  all.add(e);
  report_and_check("pooled", all, 2.0);
}

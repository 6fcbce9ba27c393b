// Issue 16: the refined u_S never claims more than the raw separation can show.
//
// A refine that corrects nothing (no effect applied, no gross error removed, no non-linearity
// corrected) reports the raw separation's S, so its error is the raw one: its u_S and u_γ must be
// the raw separation's, widened by what it declined (the fitted size of a detected effect, the
// part a plan cannot determine), never less, point by point.  A refine that corrects something
// separates the corrected readings afresh, with a lower σ̂ where the correction explained part of
// the residual, but keeps the raw separation's constant, line and bow of S and constant and line
// of γ: the covariance of those five functionals must be at least the raw one (the gauge floor,
// refine.cpp).  Found on errsep-refine-sweep --plan single, effect bump, seed 14: three readings
// of the bump removed as spikes, σ̂ 0.27 -> 0.09 um, u_S 1.38 -> 0.54 um rms with the gauge's
// share of it dropped (S error 2.59 -> 2.79 um).
//
// Cases are simulate_undeclared's (random multi-harmonic S, γ and f with random phases and
// amplitudes per seed, independent noise on every reading), seeds 1-20 at σ = 0.05/0.1/0.2 um.
#include <Eigen/Dense>
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <vector>

#include "errsep/core/refine.hpp"
#include "errsep/core/undeclared_effect_simulation.hpp"

using namespace errsep::core;

namespace {

bool corrected(const RefineResult& r) {
  bool any = r.nonlinearity.applied;
  for (bool a : r.applied)
    any = any || a;
  if (r.gross_removed)
    for (const auto& e : r.gross.errors)
      any = any || e.applied;
  return any;
}

// Covariance of the gauge functionals: S against an orthonormal basis of the polynomials of degree
// <= 2 in the position index, γ (urad) against one of degree <= 1 (remove_polynomial's).
Eigen::MatrixXd gauge_covariance(FourSensorCovariance& c, int P) {
  auto basis = [P](int degree) {
    Eigen::MatrixXd B(P, degree + 1);
    for (int i = 0; i < P; ++i)
      for (int d = 0; d <= degree; ++d)
        B(i, d) = std::pow(2.0 * i / (P - 1.0) - 1.0, d);
    return Eigen::MatrixXd(Eigen::HouseholderQR<Eigen::MatrixXd>(B).householderQ() *
                           Eigen::MatrixXd::Identity(P, degree + 1));
  };
  const Eigen::MatrixXd QS = basis(2), Qg = basis(1);
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(P, 5), B = Eigen::MatrixXd::Zero(P, 5);
  A.leftCols(3) = QS;
  B.rightCols(2) = 1e6 * Qg;
  Eigen::MatrixXd K(5, 5);
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 5; ++j)
      K(i, j) = 0.25 * (c.variance(A.col(i) + A.col(j), B.col(i) + B.col(j), {}) -
                        c.variance(A.col(i) - A.col(j), B.col(i) - B.col(j), {}));
  return K;
}

struct Tally {
  int runs = 0, nothing = 0, declined = 0, corrected = 0;
  double min_ratio_S = 1e300, min_ratio_gamma = 1e300;  // over the runs that correct nothing
  double worst_gauge = 1e300;  // min eigenvalue of K_refined − K_raw over trace(K_raw)
};

RefineResult check(UndeclaredEffect effect, double sigma, std::uint64_t seed, Tally& t,
                   const RefineOptions& opts = {}) {
  UndeclaredCaseOptions co;
  co.sigma_um = sigma;
  co.seed = seed;
  const UndeclaredCase c = simulate_undeclared(effect, co);
  const RefineResult r = refine_four_sensor(c.cfg, c.m_um, c.t_s, opts);
  ++t.runs;
  const int P = c.cfg.positions();
  REQUIRE(r.after.u_S_um.size() == P);
  REQUIRE(r.before.u_S_um.size() == P);
  INFO(to_string(effect) << " sigma " << sigma << " seed " << seed << ": " << r.brief_report());
  if (!corrected(r)) {
    ++t.nothing;
    if (!r.effects.empty()) ++t.declined;
    // The same S as the raw separation: nothing in the readings changed.
    CHECK((r.after.S_um - r.before.S_um).cwiseAbs().maxCoeff() <=
          1e-9 * (1.0 + r.before.S_um.cwiseAbs().maxCoeff()));
    const double rs = (r.after.u_S_um.array() / r.before.u_S_um.array()).minCoeff();
    const double rg = (r.after.u_gamma_rad.array() / r.before.u_gamma_rad.array()).minCoeff();
    t.min_ratio_S = std::min(t.min_ratio_S, rs);
    t.min_ratio_gamma = std::min(t.min_ratio_gamma, rg);
    // Equal up to rounding when nothing was declined (the same separation), larger when it was.
    CHECK(rs >= 1.0 - 1e-12);
    CHECK(rg >= 1.0 - 1e-12);
  } else {
    ++t.corrected;
  }
  if (r.after.covariance && r.before.covariance && r.after.covariance != r.before.covariance) {
    const Eigen::MatrixXd Kr = gauge_covariance(*r.before.covariance, P);
    const Eigen::MatrixXd Ka = gauge_covariance(*r.after.covariance, P);
    const double m =
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Ka - Kr).eigenvalues().minCoeff() /
        Kr.trace();
    t.worst_gauge = std::min(t.worst_gauge, m);
    CHECK(m >= -1e-9);
  }
  return r;
}

void report(const char* what, const Tally& t) {
  if (t.nothing == 0) {
    std::printf(
        "%s: %d runs, corrected in %d; smallest eigenvalue of (refined - raw) gauge "
        "covariance / trace %.3g\n",
        what, t.runs, t.corrected, t.worst_gauge < 1e299 ? t.worst_gauge : 0.0);
    return;
  }
  std::printf(
      "%s: %d runs, nothing corrected in %d (%d of them with effects detected and declined), "
      "corrected in %d; smallest refined/raw u over the points where nothing was corrected: S "
      "%.6f, gamma %.6f; smallest eigenvalue of (refined - raw) gauge covariance / trace %.3g\n",
      what, t.runs, t.nothing, t.declined, t.corrected, t.min_ratio_S, t.min_ratio_gamma,
      t.worst_gauge < 1e299 ? t.worst_gauge : 0.0);
}

// One case per sigma (each 3-5 s in release; the three sigmas of one effect took 9-15 s).
void sweep(UndeclaredEffect effect, double sigma, Tally& t) {
  for (std::uint64_t seed = 1; seed <= 20; ++seed)
    check(effect, sigma, seed, t);
  char what[64];
  std::snprintf(what, sizeof what, "%s at sigma %.2f", to_string(effect), sigma);
  report(what, t);
}

}  // namespace

TEST_CASE("clean data, seeds 1-20 at sigma 0.05 um: u_S, u_gamma never below the raw ones",
          "[refine][sweep]") {
  Tally t;
  sweep(UndeclaredEffect::none, 0.05, t);
  // Not vacuous: on clean data the loop corrects nothing in nearly every run (seeded: 20 of 20
  // at each sigma when this was written).
  CHECK(t.nothing >= 17);
}

TEST_CASE("clean data, seeds 1-20 at sigma 0.1 um: u_S, u_gamma never below the raw ones",
          "[refine][sweep]") {
  Tally t;
  sweep(UndeclaredEffect::none, 0.1, t);
  CHECK(t.nothing >= 17);
}

TEST_CASE("clean data, seeds 1-20 at sigma 0.2 um: u_S, u_gamma never below the raw ones",
          "[refine][sweep]") {
  Tally t;
  sweep(UndeclaredEffect::none, 0.2, t);
  CHECK(t.nothing >= 17);
}

// A drift of one configuration: detected, not identifiable from the single plan, declined
// (errsep-refine-sweep: added in 65-70 % of runs, applied in none).
TEST_CASE(
    "a declined drift of one configuration, seeds 1-20 at sigma 0.05 um: u_S never below "
    "the raw one",
    "[refine][sweep]") {
  Tally t;
  sweep(UndeclaredEffect::drift_one, 0.05, t);
  // Not vacuous: most runs detect the drift and decline it (seeded: 14 of 20 when written).
  CHECK(t.declined >= 7);
}

TEST_CASE(
    "a declined drift of one configuration, seeds 1-20 at sigma 0.1 um: u_S never below "
    "the raw one",
    "[refine][sweep]") {
  Tally t;
  sweep(UndeclaredEffect::drift_one, 0.1, t);
  CHECK(t.declined >= 7);
}

TEST_CASE(
    "a declined drift of one configuration, seeds 1-20 at sigma 0.2 um: u_S never below "
    "the raw one",
    "[refine][sweep]") {
  Tally t;
  sweep(UndeclaredEffect::drift_one, 0.2, t);
  CHECK(t.declined >= 7);
}

TEST_CASE(
    "bump taken for spikes (seed 14, sigma 0.05): the refined result keeps the raw "
    "separation's uncertainty in the gauge directions") {
  Tally t;
  // The spikes are removed only with the cluster rule off (gross_errors.hpp: adjacent spikes of
  // one configuration are a shape and, by default, not removed; this run then corrects nothing):
  // the floor is exercised by a removal that separates the readings afresh.
  RefineOptions o;
  o.gross.cluster_positions = 0;
  const RefineResult r = check(UndeclaredEffect::bump, 0.05, 14, t, o);
  report("bump seed 14", t);
  CHECK(t.corrected == 1);  // the spikes were removed: this run exercises the floor
  CHECK(t.worst_gauge < 1e299);
  // The floor did something here: the fresh separation of the readings without the spikes (σ̂
  // 0.27 -> 0.09 um) held less than the raw separation in the gauge directions, which is what
  // the refined u_S reported before (0.54 um rms against the raw 1.38).
  const auto rms = [](const Eigen::VectorXd& v) { return std::sqrt(v.squaredNorm() / v.size()); };
  std::printf("bump seed 14: u_S rms raw %.3f, refined %.3f, of which the gauge floor %.3f um\n",
              rms(r.before.u_S_um), rms(r.after.u_S_um), rms(r.u_S_gauge_um));
  CHECK(rms(r.u_S_gauge_um) > 0.5 * rms(r.before.u_S_um));
}

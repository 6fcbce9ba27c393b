// The factorisation says what it cannot do (issue 15): CHOLMOD's LDLᵀ stops only at an exactly
// zero pivot and takes a negative one silently, so before this a matrix that is indefinite (by
// construction, or to working precision) was "factorised" with success and a NaN log det.
// Asserted: an indefinite AᵀA + λ²P is refused with SolverStatus::not_positive_definite, the
// pivot and λ named; on the four-sensor system of a long scan (N = 10⁵, where AᵀA + λ²P is
// singular to working precision at some λ: the second-difference prior and the data are both
// blind to f's longest wavelengths) every λ either factorises with a finite log det or is
// refused with its pivot; the REML search and the result carry the refused λ; and a REML minimum
// next to refused λ (N = 10⁶) is flagged as not bracketed.  (The band block is now factorised by
// detail::BandLdlt, which checks every pivot as CHOLMOD's LDLᵀ did not.)
#include <Eigen/Dense>
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <string>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/four_sensor_posterior.hpp"
#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/core/tikhonov_solver.hpp"
#include "support/random_banded.hpp"

using namespace errsep::core;
using errsep::test::random_banded;

TEST_CASE("an indefinite A'A + lambda^2 P is refused with its pivot and lambda",
          "[tikhonov][failure]") {
  const int m = 40, rows = 70;
  for (const int k : {0, 2}) {
    INFO("border " << k);
    const Eigen::SparseMatrix<double> A = random_banded(rows, m, k, 4, 23u + k);
    // P = −I on one band unknown (q), 0 elsewhere: AᵀA + λ²P is indefinite once λ² exceeds
    // that unknown's information, positive definite below.
    const int q = 25;
    Eigen::SparseMatrix<double> P(m + k, m + k);
    P.insert(q, q) = -1.0;
    TikhonovSolver solver(A, k, P);
    const double small = 1e-3, large = 1e3;
    REQUIRE(solver.factorize(small) == SolverStatus::success);
    CHECK(std::isfinite(solver.log_det()));
    // The dense reference: the matrix at `large` has a negative eigenvalue.
    const Eigen::MatrixXd Ad = A;
    Eigen::MatrixXd M = Ad.transpose() * Ad;
    M(q, q) -= large * large;
    REQUIRE(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(M).eigenvalues()(0) < 0.0);
    CHECK(solver.factorize(large) == SolverStatus::not_positive_definite);
    const FactorFailure& f = solver.failure();
    CHECK(f.lambda == large);
    CHECK(f.pivot >= q);  // the pivots before q are those of a positive definite leading block
    CHECK(f.pivot < m + k);
    CHECK(f.unknowns == m + k);
    CHECK_FALSE(f.pivot_value > 0.0);
    const std::string msg = f.message();
    INFO(msg);
    CHECK(msg.find("lambda = 1000 rejected: factor not positive definite at pivot " +
                   std::to_string(f.pivot)) == 0);
    CHECK_THROWS_AS(solver.log_det(), std::logic_error);
    CHECK_THROWS_AS(solver.selected_inverse(), std::logic_error);
    double qf = 0.0;
    CHECK(solver.factorize_and_quadratic_form(large, Eigen::VectorXd::Ones(m + k), qf) ==
          SolverStatus::not_positive_definite);
    // And it recovers at a λ where the matrix is positive definite again.
    REQUIRE(solver.factorize(small) == SolverStatus::success);
    CHECK(std::isfinite(solver.log_det()));
  }
}

namespace {
// The default prior's system on the paper's spacings at N = 10⁵ (A depends on the geometry only).
struct LongScan {
  FourSensorConfig cfg{5.0, 1, 1, 5, 100000};
  FourSensorSimData sim;
  LongScan() {
    FourSensorSimOptions so;
    so.sigma_um = 0.1;
    so.seed = 15;
    sim = simulate_four_sensor(cfg, random_smooth_truth(cfg, 1515), so);
  }
};
}  // namespace

TEST_CASE("a long scan: every lambda factorises with a finite log det or is refused",
          "[tikhonov][failure][four_sensor]") {
  const LongScan s;
  PinnedSystem sys = assemble_pinned_system(s.cfg, s.sim.m_um, true);
  const Eigen::SparseMatrix<double> L = penalty_operator(s.cfg, Penalty::second_difference, sys);
  Eigen::SparseMatrix<double> P = L.transpose() * L;
  P.prune(0.0);
  TikhonovSolver solver(std::move(sys.A), sys.border, P);
  int refused = 0, tried = 0;
  for (double e = -1.0; e <= 6.01; e += 0.25, ++tried) {
    const double lambda = std::pow(10.0, e);
    INFO("lambda " << lambda);
    const SolverStatus st = solver.factorize(lambda);
    if (st == SolverStatus::success) {
      CHECK(std::isfinite(solver.log_det()));  // was NaN with "success" before
      continue;
    }
    REQUIRE(st == SolverStatus::not_positive_definite);
    ++refused;
    const FactorFailure& f = solver.failure();
    INFO(f.message());
    CHECK(f.lambda == lambda);
    CHECK(f.pivot >= 0);
    CHECK(f.pivot < f.unknowns);
    CHECK_FALSE(f.pivot_value > 0.0);
  }
  std::printf(
      "N = 1e5, second-difference prior: %d of %d lambda in [0.1, 1e6] refused (factor "
      "not positive definite)\n",
      refused, tried);
  // The condition this reproduces: at N = 10⁵ the long wavelengths leave AᵀA + λ²P singular to
  // working precision at several λ (8 of 37 here on the development machine).
  CHECK(refused >= 1);
}

TEST_CASE("the REML search and the result carry the refused lambda", "[four_sensor][failure]") {
  const LongScan s;
  FourSensorOptions o;  // the defaults: posterior, second-difference prior, REML
  o.search.threads = 2;
  const FourSensorResult r = separate_four_sensor(s.cfg, s.sim.m_um, o);
  std::printf("N = 1e5 default estimator: %zu lambda refused, %zu evaluated on the grid; %s\n",
              r.lambda_rejected.size(), r.lambda_grid.size(), r.brief_report().c_str());
  for (const std::string& why : r.lambda_rejected) {
    INFO(why);
    CHECK(why.find("rejected: factor not positive definite at pivot ") != std::string::npos);
  }
  if (r.lambda_rejected.empty()) {
    std::printf(
        "SKIPPED: no lambda of this search hit a lost pivot in this build (round-off "
        "differs between builds); the solver-level case above covers the status\n");
    return;
  }
  CHECK(r.determination_note.find("rejected because the factor") != std::string::npos);
  CHECK(r.brief_report().find("lambda rejected") != std::string::npos);
  CHECK(std::isfinite(r.u_S_um.maxCoeff()));
}

// Issue 15: at N = 10⁶ REML still falls at the last λ the factorisation accepts and every larger λ
// is refused, so the minimum is not bracketed: lambda_at_edge must say so, and the determination
// note why.  Costs one default separation at N = 10⁶ (~4 s of CPU in a release build).
TEST_CASE("a REML minimum next to refused lambda is not bracketed: at the edge (N = 1e6)",
          "[four_sensor][failure][edge]") {
  const FourSensorConfig cfg{5.0, 1, 1, 5, 1000000};
  FourSensorSimOptions so;
  so.sigma_um = 0.1;
  so.seed = 15;
  const FourSensorSimData sim = simulate_four_sensor(cfg, zhao2019_example1(cfg), so);
  FourSensorOptions o;  // the defaults: posterior, second-difference prior, REML
  o.search.threads = 2;
  const FourSensorResult r = separate_four_sensor(cfg, sim.m_um, o);
  std::printf("N = 1e6 default estimator: %s\nnote: %s\n", r.brief_report().c_str(),
              r.determination_note.c_str());
  REQUIRE_FALSE(r.lambda_grid.empty());
  const auto best = std::min_element(r.lambda_criterion.begin(), r.lambda_criterion.end()) -
                    r.lambda_criterion.begin();
  const double grid_best = r.lambda_grid[static_cast<std::size_t>(best)];
  const bool finite_above = static_cast<std::size_t>(best) + 1 < r.lambda_grid.size();
  bool refused_above = false;
  for (const std::string& why : r.lambda_rejected) {
    double l = 0.0;
    REQUIRE(std::sscanf(why.c_str(), "lambda = %lf", &l) == 1);
    refused_above = refused_above || l > grid_best;
  }
  const bool said = r.determination_note.find("minimum is not bracketed") != std::string::npos;
  if (finite_above || !refused_above) {
    // The converse: a minimum bracketed on the grid is not called unbracketed.
    CHECK_FALSE(said);
    CHECK(r.brief_report().find("minimum not bracketed") == std::string::npos);
    std::printf(
        "SKIPPED: in this build REML's grid minimum (lambda %.3g) has %s above it (round-off "
        "decides which lambda are refused); the case at depth is not reproduced\n",
        grid_best, finite_above ? "a finite lambda" : "no refused lambda");
    return;
  }
  CHECK(r.lambda_at_edge);
  CHECK(r.lambda_at_refused_edge);
  CHECK(said);
  // The brief report says the same as the note: not bracketed, not "at the edge of the range".
  CHECK(r.brief_report().find("minimum not bracketed") != std::string::npos);
  CHECK(r.brief_report().find("edge of the range") == std::string::npos);
  double noted = 0.0;
  const auto at = r.determination_note.find("the search's lambda ");
  REQUIRE(at != std::string::npos);
  REQUIRE(std::sscanf(r.determination_note.c_str() + at, "the search's lambda %lf", &noted) == 1);
  // The refinement halves the grid's spacing (one decade by default) around the grid's best.
  CHECK(std::abs(std::log10(noted / grid_best)) < 1.0);
}

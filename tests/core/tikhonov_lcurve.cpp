// CHOLMOD Tikhonov solver against a dense reference, and the L-curve curvature against finite
// differences.
#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <cmath>
#include <vector>

#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/core/four_sensor_system.hpp"
#include "errsep/core/lcurve.hpp"
#include "errsep/core/tikhonov_solver.hpp"

using namespace errsep::core;

namespace {
AugmentedSystem example_system(double sigma) {
  FourSensorConfig cfg;
  FourSensorSimOptions so;
  so.sigma_um = sigma;
  so.seed = 7;
  const auto sim = simulate_four_sensor(cfg, zhao2019_example1(cfg), so);
  return assemble_four_sensor_system(cfg, sim.m_um, CurvatureGauge::sensor_stage_without_curvature);
}
}  // namespace

TEST_CASE("CHOLMOD Tikhonov solution equals the dense one for every lambda") {
  const auto sys = example_system(0.1);
  const Eigen::MatrixXd A = Eigen::MatrixXd(sys.A);
  const Eigen::MatrixXd AtA = A.transpose() * A;
  // Without a border (CHOLMOD factorises all of AᵀA) and with the Δe border eliminated by its
  // Schur complement: both must give the dense solution and the dense quadratic form.  With the
  // border AᵀA is formed from A's rows in band storage (every row spans at most s2+s3+s4+1
  // samples of f); without it the Δe columns make every data row wide (cholmod_aat then).
  for (int border : {0, 4}) {
    TikhonovSolver solver(sys.A, border);
    CHECK(solver.stats().banded_normal == (border > 0));
    for (double lambda : {0.0, 1e-3, 0.05, 1.0, 10.0}) {
      REQUIRE(solver.factorize(lambda) == SolverStatus::success);
      const Eigen::VectorXd x = solver.solve(sys.b);
      const Eigen::MatrixXd M =
          AtA + lambda * lambda * Eigen::MatrixXd::Identity(A.cols(), A.cols());
      const Eigen::VectorXd ref = M.ldlt().solve(A.transpose() * sys.b);
      INFO("border = " << border << ", lambda = " << lambda);
      // Tolerance scaled by the condition number of M and machine epsilon.
      Eigen::JacobiSVD<Eigen::MatrixXd> svd(M);
      const double cond = svd.singularValues()(0) / svd.singularValues().tail(1)(0);
      CHECK((x - ref).norm() <= 10 * cond * 2.2e-16 * ref.norm());
      const double q_ref = ref.dot(M.ldlt().solve(ref));
      CHECK(std::abs(solver.inverse_quadratic_form(ref) - q_ref) <= 10 * cond * 2.2e-16 * q_ref);
      // The fused factorisation and solve (the border's and the right-hand side's forward
      // substitutions in one pass) gives the same solution.
      Eigen::VectorXd xf;
      REQUIRE(solver.factorize_and_solve(lambda, A.transpose() * sys.b, xf) ==
              SolverStatus::success);
      CHECK((xf - ref).norm() <= 10 * cond * 2.2e-16 * ref.norm());
    }
    CHECK(solver.stats().factorizations == 10);
    // The Δe border couples to f through Eq. (3)'s C, of rank 2: two solves per λ, not four.
    CHECK(solver.stats().border_rank == (border > 0 ? 2 : 0));
  }
}

TEST_CASE("a row wider than a band: AtA by the general product, the same solutions") {
  // A row tying f(x_0) to f(x_{N-1}) (bandwidth N - 1 > 64): the banded formation refuses it and
  // cholmod_aat forms AᵀA; the solutions must still be the dense ones.
  const auto sys = example_system(0.1);
  const Eigen::Index r = sys.A.rows(), n = sys.A.cols();
  Eigen::SparseMatrix<double> A2(r + 1, n);
  {
    std::vector<Eigen::Triplet<double>> t;
    for (int k = 0; k < sys.A.outerSize(); ++k)
      for (Eigen::SparseMatrix<double>::InnerIterator it(sys.A, k); it; ++it)
        t.emplace_back(static_cast<int>(it.row()), static_cast<int>(it.col()), it.value());
    t.emplace_back(static_cast<int>(r), 0, 0.5);
    t.emplace_back(static_cast<int>(r), static_cast<int>(n - 5), -0.5);
    A2.setFromTriplets(t.begin(), t.end());
  }
  Eigen::VectorXd b2(r + 1);
  b2 << sys.b, 0.3;
  const Eigen::MatrixXd A = Eigen::MatrixXd(A2);
  for (int border : {0, 4}) {
    TikhonovSolver solver(A2, border);
    CHECK_FALSE(solver.stats().banded_normal);
    for (double lambda : {1e-3, 0.05, 1.0}) {
      REQUIRE(solver.factorize(lambda) == SolverStatus::success);
      const Eigen::MatrixXd M =
          A.transpose() * A + lambda * lambda * Eigen::MatrixXd::Identity(n, n);
      const Eigen::VectorXd ref = M.ldlt().solve(A.transpose() * b2);
      Eigen::JacobiSVD<Eigen::MatrixXd> svd(M);
      const double cond = svd.singularValues()(0) / svd.singularValues().tail(1)(0);
      INFO("border = " << border << ", lambda = " << lambda);
      CHECK((solver.solve(b2) - ref).norm() <= 10 * cond * 2.2e-16 * ref.norm());
    }
  }
}

TEST_CASE("spacings with a common factor are refused: A would be rank-deficient") {
  // Shown on the dense matrix: s = (2, 2, 2) makes the alternating profile invisible.
  FourSensorConfig bad{5.0, 2, 2, 2, 40};
  std::string why;
  CHECK_FALSE(bad.is_valid(&why));
  CHECK_THAT(why, Catch::Contains("share the factor 2"));
  const Eigen::MatrixXd C = combination_matrix(bad);
  Eigen::Vector4d alternating;
  for (int j = 0; j < 4; ++j)
    alternating(j) = (bad.offsets_samples()[static_cast<size_t>(j)] % 2) ? -1.0 : 1.0;
  CHECK((C * alternating).norm() < 1e-12);  // every row blind to f(x_n) = (-1)^n
}

TEST_CASE("closed-form L-curve curvature matches finite differences and peaks at the corner") {
  const auto sys = example_system(0.1);
  TikhonovSolver solver(sys.A);
  auto point = [&](double lambda) {
    REQUIRE(solver.factorize(lambda) == SolverStatus::success);
    return lcurve_point(solver, sys.b, solver.solve(sys.b));
  };
  for (double lambda : {1e-3, 5e-3, 3e-2, 0.3, 1.5}) {
    const double h = 1e-3;  // step in ln λ
    const auto pm = point(lambda * std::exp(-h)), p0 = point(lambda),
               pp = point(lambda * std::exp(h));
    auto X = [](const LCurvePoint& p) { return std::log(p.residual_norm); };
    auto Y = [](const LCurvePoint& p) { return std::log(p.solution_norm); };
    const double x1 = (X(pp) - X(pm)) / (2 * h), y1 = (Y(pp) - Y(pm)) / (2 * h);
    const double x2 = (X(pp) - 2 * X(p0) + X(pm)) / (h * h);
    const double y2 = (Y(pp) - 2 * Y(p0) + Y(pm)) / (h * h);
    const double kappa_fd = (x1 * y2 - x2 * y1) / std::pow(x1 * x1 + y1 * y1, 1.5);
    INFO("lambda " << lambda << " closed form " << p0.curvature << " finite difference "
                   << kappa_fd);
    CHECK(p0.curvature == Approx(kappa_fd).epsilon(0.05).margin(1e-3));
  }
  const auto lc = lcurve_corner(solver, sys.b, {});
  CHECK_FALSE(lc.at_edge);
  CHECK(lc.points.size() == 50);
  for (const auto& p : lc.points)
    CHECK(p.curvature <= lc.curvature_corner + 1e-12);
  // The corner sits where the residual starts to grow: within 10 % of the smallest residual.
  double rmin = lc.points.front().residual_norm;
  REQUIRE(solver.factorize(lc.lambda_corner) == SolverStatus::success);
  const double rc = (sys.A * solver.solve(sys.b) - sys.b).norm();
  CHECK(rc < 1.1 * rmin);
}

TEST_CASE("an L-curve without an interior corner is flagged at_edge") {
  // A = I, b = 1: ‖r‖ and ‖x‖ trade smoothly and the curvature is negative everywhere.
  const int n = 20;
  Eigen::SparseMatrix<double> A(n, n);
  for (int i = 0; i < n; ++i)
    A.insert(i, i) = 1.0;
  A.makeCompressed();
  TikhonovSolver solver(A);
  LCurveOptions o;
  o.count = 40;
  o.lambda_min = 1e-4;
  o.lambda_max = 1e-1;
  const auto lc = lcurve_corner(solver, Eigen::VectorXd::Ones(n), o);
  CHECK(lc.at_edge);
}

TEST_CASE("the threaded L-curve sweep gives the same curve as the sequential one") {
  const auto sys = example_system(0.1);
  TikhonovSolver s1(sys.A), s2(sys.A);
  LCurveOptions o;
  o.count = 41;
  const auto seq = lcurve_corner(s1, sys.b, o);
  o.threads = 2;
  const auto par = lcurve_corner(s2, sys.b, o);
  REQUIRE(par.points.size() == seq.points.size());
  for (std::size_t i = 0; i < seq.points.size(); ++i) {
    CHECK(par.points[i].lambda == seq.points[i].lambda);
    CHECK(par.points[i].residual_norm == Approx(seq.points[i].residual_norm).epsilon(1e-12));
    CHECK(par.points[i].curvature == Approx(seq.points[i].curvature).epsilon(1e-9));
  }
  CHECK(par.lambda_corner == Approx(seq.lambda_corner).epsilon(1e-9));
  CHECK(par.factorizations == seq.factorizations);
}

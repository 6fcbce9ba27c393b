// The posterior estimator against dense references written here from its definition
// (four_sensor_posterior.hpp): the general-form solver (penalty reaching the border) against a
// dense solve, its log det and selected inverse against the dense inverse; the separation's f, S,
// γ and their uncertainties against a dense model with unknowns f(x_1..x_{N−2}), η (no pinned
// middle, no bow unknown), its posterior σ²(AᵀA + λ²P)⁻¹, and the gauge applied as a projection.
#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <limits>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/four_sensor_simulation.hpp"
#include "support/random_banded.hpp"

using namespace errsep::core;
using errsep::test::random_banded;

TEST_CASE("general-form solver: penalty on band and border equals the dense solve",
          "[tikhonov][penalty]") {
  const int m = 40, k = 3, rows = 70;
  const Eigen::SparseMatrix<double> A = random_banded(rows, m, k, 4, 7);
  // P: second differences on the band, a dense coupling of the last border unknown, and a
  // positive border diagonal there; the other two border unknowns flat.
  Eigen::MatrixXd Pd = Eigen::MatrixXd::Zero(m + k, m + k);
  for (int i = 0; i + 2 < m; ++i) {
    Eigen::VectorXd l = Eigen::VectorXd::Zero(m + k);
    l(i) = 1;
    l(i + 1) = -2;
    l(i + 2) = 1;
    l(m + 2) = 0.1 * std::sin(i);
    Pd += l * l.transpose();
  }
  Pd(m + 2, m + 2) += 0.5;
  const Eigen::SparseMatrix<double> P = Pd.sparseView();
  TikhonovSolver solver(A, k, P);
  const Eigen::MatrixXd Ad = A;
  Eigen::VectorXd b(rows);
  for (int r = 0; r < rows; ++r)
    b(r) = std::cos(0.3 * r);
  for (const double lambda : {0.05, 0.7, 3.0}) {
    REQUIRE(solver.factorize(lambda) == SolverStatus::success);
    const Eigen::MatrixXd M = Ad.transpose() * Ad + lambda * lambda * Pd;
    const Eigen::VectorXd x_ref = M.ldlt().solve(Ad.transpose() * b);
    const Eigen::VectorXd x = solver.solve(b);
    CHECK((x - x_ref).norm() <= 1e-9 * x_ref.norm());
    CHECK(std::abs(solver.log_det() - std::log(M.determinant())) <=
          1e-9 * std::abs(solver.log_det()));
    const Eigen::MatrixXd Z = M.inverse();
    const SelectedInverse z = solver.selected_inverse();
    double worst = 0.0;
    for (int i = 0; i < m + k; ++i)
      for (int j = 0; j < m + k; ++j)
        if (i >= m || j >= m || std::abs(i - j) <= 3)
          worst = std::max(worst, std::abs(z(i, j) - Z(i, j)));
    CHECK(worst <= 1e-9 * Z.cwiseAbs().maxCoeff());
    const double tr = (Z * Pd).trace();
    CHECK(std::abs(solver.trace_inverse_penalty(z) - tr) <= 1e-9 * std::abs(tr));
    const double edf = (Z * (Ad.transpose() * Ad)).trace();
    CHECK(std::abs(solver.trace_inverse_normal(z) - edf) <= 1e-9 * std::abs(edf));
    const Eigen::VectorXd Px = solver.apply_penalty(x);
    CHECK((Px - Pd * x).norm() <= 1e-12 * (Pd * x).norm());
  }
}

namespace {

struct DenseRef {
  Eigen::VectorXd f, S, g, u_f, u_S, u_g;
  double edf = 0.0;  ///< tr(A·M⁻¹·Aᵀ): the hat matrix's trace
};

// The model of four_sensor_posterior.hpp, dense: unknowns f(x_1..x_{N−2}), η; prior λ²‖Lf‖²
// (L = second differences of the whole f with its ends at 0, or I); for least squares the bow
// is left free and taken out by the pseudo-inverse.  Then the gauge: f_G = f − (bow·f/‖bow‖²)·bow
// with η moved along, and S, γ by the least-squares line through the four residuals.
DenseRef dense_reference(const FourSensorConfig& cfg, const Eigen::MatrixXd& m, Penalty pen,
                         double lambda, double sigma) {
  const int N = cfg.N, P = cfg.positions(), n = N - 2 + 2;
  const auto k = cfg.offsets_samples();
  const auto O = cfg.offsets_mm();
  const Eigen::Matrix<double, 4, 2> Q = reading_combinations(cfg);
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(2 * P, n);
  Eigen::VectorXd b(2 * P);
  for (int p = 0; p < P; ++p)
    for (int r = 0; r < 2; ++r) {
      for (int j = 0; j < 4; ++j) {
        const int i = p + k[static_cast<std::size_t>(j)];
        if (i > 0 && i < N - 1) A(2 * p + r, i - 1) += Q(j, r);
      }
      A(2 * p + r, N - 2 + r) = 1.0;
      b(2 * p + r) = Q.col(r).dot(m.row(p).transpose());
    }
  Eigen::MatrixXd Pm = Eigen::MatrixXd::Zero(n, n);
  if (pen == Penalty::second_difference) {
    for (int i = 0; i + 2 < N; ++i) {
      Eigen::VectorXd l = Eigen::VectorXd::Zero(n);
      for (int d = 0; d < 3; ++d)
        if (i + d > 0 && i + d < N - 1) l(i + d - 1) = d == 1 ? -2.0 : 1.0;
      Pm += l * l.transpose();
    }
  } else if (pen == Penalty::identity) {
    Pm.topLeftCorner(N - 2, N - 2).setIdentity();
  }
  const Eigen::MatrixXd M = A.transpose() * A + lambda * lambda * Pm;
  const Eigen::MatrixXd Minv =
      pen == Penalty::none ? Eigen::MatrixXd(M.completeOrthogonalDecomposition().pseudoInverse())
                           : Eigen::MatrixXd(M.inverse());
  const Eigen::VectorXd x = Minv * A.transpose() * b;
  // Gauge: x_G = T·x with T = I − nvec·gᵀ/(g·nvec).
  const double L0 = cfg.reference_length_mm();
  Eigen::VectorXd bow(N), nvec = Eigen::VectorXd::Zero(n), g = Eigen::VectorXd::Zero(n);
  for (int i = 0; i < N; ++i) {
    const double t = static_cast<double>(i) / (N - 1);
    bow(i) = t * (1 - t);
  }
  nvec.head(N - 2) = bow.segment(1, N - 2);
  g.head(N - 2) = bow.segment(1, N - 2);
  Eigen::Vector4d o2;
  for (int j = 0; j < 4; ++j)
    o2(j) = O[static_cast<std::size_t>(j)] * O[static_cast<std::size_t>(j)];
  nvec.tail(2) = Q.transpose() * o2 / (L0 * L0);
  const Eigen::MatrixXd T = Eigen::MatrixXd::Identity(n, n) - nvec * g.transpose() / g.dot(nvec);
  const Eigen::VectorXd xG = T * x;
  const Eigen::MatrixXd SG = sigma * sigma * T * Minv * T.transpose();
  // e from η with e_1 = e_4 = 0; S, γ from the line through the four residuals.
  Eigen::Matrix2d K;
  K << Q(1, 0), Q(2, 0), Q(1, 1), Q(2, 1);
  Eigen::Matrix<double, 4, 2> E = Eigen::Matrix<double, 4, 2>::Zero();
  E.middleRows<2>(1) = K.inverse();
  Eigen::Matrix<double, 4, 2> X;
  for (int j = 0; j < 4; ++j)
    X.row(j) << 1.0, O[static_cast<std::size_t>(j)];
  const Eigen::Matrix<double, 2, 4> W = (X.transpose() * X).inverse() * X.transpose();
  DenseRef ref;
  ref.edf = (A * Minv * A.transpose()).trace();
  ref.f = Eigen::VectorXd::Zero(N);
  ref.u_f = Eigen::VectorXd::Zero(N);
  ref.f.segment(1, N - 2) = xG.head(N - 2);
  for (int i = 1; i < N - 1; ++i)
    ref.u_f(i) = std::sqrt(SG(i - 1, i - 1));
  ref.S.resize(P);
  ref.g.resize(P);
  ref.u_S.resize(P);
  ref.u_g.resize(P);
  for (int p = 0; p < P; ++p) {
    // r = m − F·x_G − E·η: its Jacobian in x_G is −J.
    Eigen::MatrixXd J = Eigen::MatrixXd::Zero(4, n);
    for (int j = 0; j < 4; ++j) {
      const int i = p + k[static_cast<std::size_t>(j)];
      if (i > 0 && i < N - 1) J(j, i - 1) = 1.0;
    }
    J.rightCols(2) = E;
    const Eigen::Vector4d r = m.row(p).transpose() - J * xG;
    ref.S(p) = W.row(0).dot(r);
    ref.g(p) = 1e-3 * W.row(1).dot(r);
    const Eigen::RowVectorXd hS = W.row(0) * J, hg = W.row(1) * J;
    ref.u_S(p) = std::sqrt(sigma * sigma * W.row(0).squaredNorm() + hS * SG * hS.transpose());
    ref.u_g(p) =
        1e-3 * std::sqrt(sigma * sigma * W.row(1).squaredNorm() + hg * SG * hg.transpose());
  }
  return ref;
}

void compare(const FourSensorResult& r, const DenseRef& d, double tol) {
  auto rel = [](const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
    return (a - b).cwiseAbs().maxCoeff() / std::max(1e-300, b.cwiseAbs().maxCoeff());
  };
  CHECK(rel(r.f_um, d.f) <= tol);
  CHECK(rel(r.S_um, d.S) <= tol);
  CHECK(rel(r.gamma_rad, d.g) <= tol);
  CHECK(rel(r.u_f_um, d.u_f) <= tol);
  CHECK(rel(r.u_S_um, d.u_S) <= tol);
  CHECK(rel(r.u_gamma_rad, d.u_g) <= tol);
}

}  // namespace

TEST_CASE("posterior separation equals the dense model, with and without a prior",
          "[four_sensor][posterior]") {
  FourSensorConfig cfg;
  cfg.N = 41;
  const SlidewayTruth truth = random_smooth_truth(cfg, 3);
  FourSensorSimOptions so;
  so.sigma_um = 0.1;
  so.seed = 11;
  const FourSensorSimData sim = simulate_four_sensor(cfg, truth, so);
  for (const Penalty pen : {Penalty::second_difference, Penalty::identity, Penalty::none}) {
    INFO(to_string(pen));
    FourSensorOptions o;
    o.penalty = pen;
    o.rule = pen == Penalty::none ? LambdaRule::least_squares : LambdaRule::fixed;
    o.fixed_lambda = 0.3;
    const FourSensorResult r = separate_four_sensor(cfg, sim.m_um, o);
    const DenseRef d =
        dense_reference(cfg, sim.m_um, pen, pen == Penalty::none ? 0.0 : 0.3, r.sigma_um);
    compare(r, d, 1e-8);
    // The effective degrees of freedom (the collapse rule's edf_f = edf − 2) are the dense
    // hat matrix's trace: the pinned middle and the bow unknown only reparametrise f.
    if (pen != Penalty::none) CHECK(r.edf == Approx(d.edf).epsilon(1e-8));
    // The covariance object agrees with the per-point figures.
    const int p = 7;
    Eigen::VectorXd a = Eigen::VectorXd::Zero(cfg.positions());
    a(p) = 1.0;
    CHECK(std::sqrt(r.covariance->variance(a, {}, {})) == Approx(r.u_S_um(p)).epsilon(1e-9));
    const Eigen::MatrixXd V = r.covariance->covariance_S({p, p + 3});
    CHECK(std::sqrt(V(0, 0)) == Approx(r.u_S_um(p)).epsilon(1e-9));
    Eigen::VectorXd a2 = Eigen::VectorXd::Zero(cfg.positions());
    a2(p) = 1.0;
    a2(p + 3) = -1.0;
    CHECK(r.covariance->variance(a2, {}, {}) ==
          Approx(V(0, 0) + V(1, 1) - 2 * V(0, 1)).epsilon(1e-9));
  }
}

TEST_CASE("posterior separation is exact for noise-free data", "[four_sensor][posterior]") {
  FourSensorConfig cfg;
  cfg.N = 120;
  const SlidewayTruth truth = random_smooth_truth(cfg, 5);
  const FourSensorSimData sim = simulate_four_sensor(cfg, truth, {});
  FourSensorOptions o;
  o.rule = LambdaRule::least_squares;
  const FourSensorResult r = separate_four_sensor(cfg, sim.m_um, o);
  CHECK((r.S_um - sim.S_um).cwiseAbs().maxCoeff() <= 1e-8);
  CHECK((r.gamma_rad - sim.gamma_rad).cwiseAbs().maxCoeff() <= 1e-11);
  CHECK((r.f_um - sim.f_um).cwiseAbs().maxCoeff() <= 1e-8);
}

// The collapse rule reads edf_f, so edf_f must fall as λ grows (a stronger prior leaves f fewer
// degrees of freedom) at every scan length.  Before it was summed directly, n − λ²·tr(M⁻¹P) lost
// the answer to cancellation on long scans: at N = 10⁶ edf_f came out 3.4 at λ 9306 and 59.6 at
// λ 9733.  Here at N = 2·10⁵ over the range the REML search visits around the collapse.
TEST_CASE("edf_f falls monotonically with lambda on a long scan", "[four_sensor][posterior][edf]") {
  FourSensorConfig cfg{5.0, 1, 1, 5, 200000};
  FourSensorSimOptions so;
  so.sigma_um = 0.1;
  const FourSensorSimData sim = simulate_four_sensor(cfg, zhao2019_example1(cfg), so);
  PinnedSystem sys = assemble_pinned_system(cfg, sim.m_um, true);
  const Eigen::SparseMatrix<double> L = penalty_operator(cfg, Penalty::second_difference, sys);
  Eigen::SparseMatrix<double> Pm = L.transpose() * L;
  Pm.prune(0.0);
  TikhonovSolver solver(std::move(sys.A), sys.border, Pm);
  const auto n = static_cast<double>(solver.A().cols());
  // Each step falls, up to round-off of 10⁻³ in edf (the rule compares edf_f with 1; near the
  // top of the range edf_f is ~10⁻³ and its last digits are round-off).  The difference
  // n − λ²·tr(M⁻¹P), printed beside it, comes out negative by up to 5·10⁵ there.
  // A λ whose factor loses its positive pivots to round-off is refused (issue 15: at N = 2·10⁵
  // λ = 3.16·10⁴ here); its edf was computed from a broken factor before.  The others must fall.
  double last = std::numeric_limits<double>::infinity();
  int accepted = 0;
  for (double log_lambda = 1.0; log_lambda <= 5.0 + 1e-9; log_lambda += 0.5) {
    const double lambda = std::pow(10.0, log_lambda);
    if (solver.factorize(lambda) != SolverStatus::success) {
      std::printf("%s\n", solver.failure().message().c_str());
      continue;
    }
    ++accepted;
    const SelectedInverse z = solver.selected_inverse();
    const double edf = solver.trace_inverse_normal(z);
    const double edf_difference = n - lambda * lambda * solver.trace_inverse_penalty(z);
    std::printf("lambda %10.4g  edf %12.6g  (n - lambda^2 tr(M^-1 P): %12.6g)\n", lambda, edf,
                edf_difference);
    CHECK(edf > 2.0);  // η̃ is never penalised
    CHECK(edf <= n);
    CHECK(edf < last + 1e-3);
    last = edf;
  }
  CHECK(accepted >= 7);  // of 9
}

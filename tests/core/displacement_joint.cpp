// The displacement method's joint estimate (core/displacement_joint.hpp) against an independent
// dense least-squares reference written here from the paper's equations (Haramiishi 2024, Eqs.
// 1-3, 10-19, 27), on random stages; and against the paper's row-by-row path at the paper's noise.
#include <Eigen/Dense>
#include <Eigen/SparseCore>
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "errsep/core/displacement_joint.hpp"
#include "errsep/core/displacement_residuals.hpp"
#include "errsep/core/displacement_simulation.hpp"
#include "errsep/core/sparse_least_squares.hpp"
#include "errsep/core/two_axis_displacement.hpp"
#include "support/displacement_cases.hpp"

using namespace errsep::core;
using errsep::test::gauged_truth;
using errsep::test::random_two_axis_truth;

namespace {

constexpr double kSigmaEddy = 0.16, kSigmaContact = 0.29;  // the paper's section 3.1

/// Dense weighted least squares of the whole two-axis measurement, unknowns
/// [m1 m2 m3 m4 (nx·ny each), w (nx·ny), r1 r2 (x_p..x_{nx−1+p}), r3 r4 (y_q..y_{ny−1+q})],
/// r at the first p (q) samples fixed at 0.  Rows: every reading of sensors 1-4 in both scans
/// weighted 1/σ_e, every reading of sensor 0 weighted 1/σ_0, s0 = w + m_w (Eq. 27 or 20-21).
struct DenseTwoAxis {
  Eigen::VectorXd x;
  Eigen::MatrixXd cov;
  Eigen::Index nx, ny, px, py;
  Eigen::Index m(int k, Eigen::Index i, Eigen::Index j) const { return k * nx * ny + j * nx + i; }
  Eigen::Index w(Eigen::Index i, Eigen::Index j) const { return 4 * nx * ny + j * nx + i; }
  Eigen::Index r(int k, Eigen::Index a) const {  // -1: fixed by the gauge
    const Eigen::Index base = 5 * nx * ny;
    if (k < 2) return a < px ? -1 : base + k * nx + a - px;
    return a < py ? -1 : base + 2 * nx + (k - 2) * ny + a - py;
  }
};

DenseTwoAxis dense_two_axis(const TwoAxisScan& s, const TwoAxisOptions& o, bool rotation,
                            double sigma_e, double sigma_0) {
  DenseTwoAxis d;
  d.nx = s.x_mm.size();
  d.ny = s.y_mm.size();
  d.px = std::lround(o.displacement_x_mm / o.dx_mm);
  d.py = std::lround(o.displacement_y_mm / o.dy_mm);
  const Eigen::Index n = 5 * d.nx * d.ny + 2 * d.nx + 2 * d.ny;
  const bool rep = s.s0_2_um.size() > 0;
  const Eigen::Index rows = (8 + (rep ? 2 : 1)) * d.nx * d.ny;
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(rows, n);
  Eigen::VectorXd b(rows);
  Eigen::Index row = 0;
  const Eigen::MatrixXd* s1[4] = {&s.s1_1_um, &s.s2_1_um, &s.s3_1_um, &s.s4_1_um};
  const Eigen::MatrixXd* s2[4] = {&s.s1_2_um, &s.s2_2_um, &s.s3_2_um, &s.s4_2_um};
  const double kx = o.geometry.l_xw_mm / o.geometry.l_xs_mm;
  for (Eigen::Index j = 0; j < d.ny; ++j)
    for (Eigen::Index i = 0; i < d.nx; ++i) {
      for (int k = 0; k < 4; ++k) {
        const Eigen::Index along = k < 2 ? i : j, p = k < 2 ? d.px : d.py;
        for (int scan = 0; scan < 2; ++scan) {
          a(row, d.m(k, i, j)) = 1 / sigma_e;  // Eqs. (11)-(14), (16)-(19)
          const Eigen::Index ri = d.r(k, along + (scan ? p : 0));
          if (ri >= 0) a(row, ri) = 1 / sigma_e;
          b(row++) = (scan ? *s2[k] : *s1[k])(i, j) / sigma_e;
        }
      }
      const double ky = (o.geometry.l_yw_mm + o.geometry.l_yw_per_x * (s.x_mm(i) - s.x_mm(0))) /
                        o.geometry.l_ys_mm;
      // Eq. (27): m_w = m2 + m4 − (m2 − m1)·kx − (m4 − m3)·ky; Eqs. (20)-(21): m2 + m4.
      const double c[4] = {rotation ? kx : 0.0, rotation ? 1 - kx : 1.0, rotation ? ky : 0.0,
                           rotation ? 1 - ky : 1.0};
      for (int scan = 0; scan < (rep ? 2 : 1); ++scan) {
        a(row, d.w(i, j)) = 1 / sigma_0;  // Eq. (10)
        for (int k = 0; k < 4; ++k)
          a(row, d.m(k, i, j)) = c[k] / sigma_0;
        b(row++) = (scan ? s.s0_2_um : s.s0_1_um)(i, j) / sigma_0;
      }
    }
  // Drop the gauge's columns (all zero).
  std::vector<Eigen::Index> keep;
  for (Eigen::Index q = 0; q < n; ++q)
    if (a.col(q).squaredNorm() > 0) keep.push_back(q);
  Eigen::MatrixXd ak(rows, static_cast<Eigen::Index>(keep.size()));
  for (std::size_t q = 0; q < keep.size(); ++q)
    ak.col(static_cast<Eigen::Index>(q)) = a.col(keep[q]);
  const Eigen::MatrixXd ata = ak.transpose() * ak;
  const Eigen::VectorXd xk = ak.colPivHouseholderQr().solve(b);
  const Eigen::MatrixXd covk = ata.inverse();
  d.x = Eigen::VectorXd::Zero(n);
  d.cov = Eigen::MatrixXd::Zero(n, n);
  for (std::size_t q = 0; q < keep.size(); ++q) {
    d.x(keep[q]) = xk(static_cast<Eigen::Index>(q));
    for (std::size_t q2 = 0; q2 < keep.size(); ++q2)
      d.cov(keep[q], keep[q2]) = covk(static_cast<Eigen::Index>(q), static_cast<Eigen::Index>(q2));
  }
  return d;
}

}  // namespace

TEST_CASE("sparse least squares equals a dense solve, its inverse diagonal the dense inverse's") {
  std::mt19937_64 rng(11);
  std::normal_distribution<double> nd;
  std::uniform_int_distribution<int> col(0, 39);
  for (int trial = 0; trial < 5; ++trial) {
    // 40 unknowns, 120 observations of 3 unknowns each (plus one per unknown: full rank).
    std::vector<Eigen::Triplet<double>> t;
    for (int o = 0; o < 120; ++o)
      for (int e = 0; e < 3; ++e)
        t.emplace_back(col(rng), o, nd(rng));
    for (int u = 0; u < 40; ++u)
      t.emplace_back(u, 120 + u, 1.0);
    Eigen::SparseMatrix<double> at(40, 160);
    at.setFromTriplets(t.begin(), t.end());
    at.makeCompressed();
    Eigen::VectorXd b(160);
    for (auto& v : b)
      v = nd(rng);
    const Eigen::MatrixXd a = Eigen::MatrixXd(at).transpose();
    const Eigen::MatrixXd ata = a.transpose() * a;
    const Eigen::VectorXd x_dense = ata.llt().solve(a.transpose() * b);
    const Eigen::VectorXd diag_dense = ata.inverse().diagonal();
    for (const bool natural : {false, true}) {
      SparseLeastSquaresOptions o;
      o.natural_ordering = natural;
      const SparseLeastSquares ls(at, o);
      REQUIRE(ls.status() == SparseLeastSquaresStatus::success);
      const double scale = x_dense.cwiseAbs().maxCoeff();
      CHECK((ls.solve(b) - x_dense).cwiseAbs().maxCoeff() < 1e-10 * scale);
      CHECK((ls.inverse_diagonal() - diag_dense).cwiseAbs().maxCoeff() <
            1e-10 * diag_dense.maxCoeff());
    }
  }
  // A dependent column (an unfixed gauge) is reported, not solved.
  Eigen::SparseMatrix<double> at(2, 3);
  at.insert(0, 0) = 1;
  at.insert(1, 0) = 1;
  at.insert(0, 1) = 2;
  at.insert(1, 1) = 2;
  at.insert(0, 2) = 1;
  at.insert(1, 2) = 1;
  at.makeCompressed();
  const SparseLeastSquares singular(at);
  CHECK(singular.status() == SparseLeastSquaresStatus::not_positive_definite);
  CHECK_THROWS_AS(singular.solve(Eigen::VectorXd::Ones(3)), std::logic_error);
}

TEST_CASE("two axes: the joint estimate and its u equal a dense weighted least-squares reference") {
  // Small grids, random stages with roll and pitch, the paper's noise, d = 1 and 2 samples, with
  // and without sensor 0 read twice, rotation correction on and off, a traverse error's u.
  struct Case {
    int nx, ny;
    double dx_mm, dy_mm;
    bool s0_twice;
    RotationCorrection rot;
    double d_sigma_mm;
  };
  const Case cases[] = {{6, 5, 5, 5, true, RotationCorrection::on, 0.0},
                        {5, 7, 5, 10, false, RotationCorrection::off, 0.0},
                        {7, 6, 10, 5, true, RotationCorrection::on, 0.05}};
  std::uint64_t seed = 300;
  for (const auto& c : cases) {
    ++seed;
    TwoAxisSimOptions so;
    so.nx = c.nx;
    so.ny = c.ny;
    so.eddy_sensor.noise_sigma_um = kSigmaEddy;
    so.contact_sensor.noise_sigma_um = kSigmaContact;
    so.record_s0_scan2 = c.s0_twice;
    so.displacement_x_mm = c.dx_mm;
    so.displacement_y_mm = c.dy_mm;
    so.seed = seed;
    const auto truth = random_two_axis_truth(seed, 50.0);
    const auto sim = simulate_two_axis(truth, so);
    TwoAxisOptions o;
    o.displacement_x_mm = c.dx_mm;  // d = dx_mm: p = 1 or 2 samples of 5 mm
    o.displacement_y_mm = c.dy_mm;
    o.chain_join = ChainJoin::given_initial_values;  // the dense reference's gauge
    o.rotation = c.rot;
    o.displacement_sigma_mm = c.d_sigma_mm;
    const auto j = separate_two_axis(sim.scan, o);
    REQUIRE(j.solver == TwoAxisSolver::joint);
    const bool rot = c.rot == RotationCorrection::on;
    REQUIRE(j.rotation_corrected == rot);
    const auto d = dense_two_axis(sim.scan, o, rot, j.sigma_reference_um, j.sigma_workpiece_um);
    // σ̂ of the reference sensors: residual sum of squares of their rows over the redundancy.
    double tol_scale = 1 + sim.scan.s0_1_um.cwiseAbs().maxCoeff();
    const double eps = 1e-9 * tol_scale;
    double worst = 0, worst_u = 0;
    for (Eigen::Index jj = 0; jj < c.ny; ++jj)
      for (Eigen::Index i = 0; i < c.nx; ++i) {
        worst = std::max(worst, std::abs(j.w_um(i, jj) - d.x(d.w(i, jj))));
        const Eigen::MatrixXd* ms[4] = {&j.m1x_um, &j.m2x_um, &j.m3y_um, &j.m4y_um};
        const Eigen::MatrixXd* us[4] = {&j.u_m1x_um, &j.u_m2x_um, &j.u_m3y_um, &j.u_m4y_um};
        for (int k = 0; k < 4; ++k) {
          worst = std::max(worst, std::abs((*ms[k])(i, jj) - d.x(d.m(k, i, jj))));
          if (c.d_sigma_mm == 0)
            worst_u = std::max(worst_u, std::abs((*us[k])(i, jj) -
                                                 std::sqrt(d.cov(d.m(k, i, jj), d.m(k, i, jj)))));
        }
        if (c.d_sigma_mm == 0)
          worst_u = std::max(worst_u,
                             std::abs(j.u_w_um(i, jj) - std::sqrt(d.cov(d.w(i, jj), d.w(i, jj)))));
      }
    for (Eigen::Index i = 0; i < c.nx; ++i) {
      worst = std::max(worst, std::abs(j.r1x_um(i, 0) - (d.r(0, i) < 0 ? 0 : d.x(d.r(0, i)))));
      worst = std::max(worst, std::abs(j.r2x_um(i, 0) - (d.r(1, i) < 0 ? 0 : d.x(d.r(1, i)))));
      if (c.d_sigma_mm == 0 && d.r(0, i) >= 0)
        worst_u =
            std::max(worst_u, std::abs(j.u_r1x_um(i, 0) - std::sqrt(d.cov(d.r(0, i), d.r(0, i)))));
    }
    for (Eigen::Index jj = 0; jj < c.ny; ++jj)
      worst = std::max(worst, std::abs(j.r4y_um(0, jj) - (d.r(3, jj) < 0 ? 0 : d.x(d.r(3, jj)))));
    INFO("grid " << c.nx << "x" << c.ny << ", d " << c.dx_mm << "/" << c.dy_mm << " mm");
    CHECK(worst < eps);
    CHECK(worst_u < 1e-9);
    if (c.d_sigma_mm > 0) {
      // u with the traverse's contribution: larger, by the sensitivity the dense system gives.
      const Eigen::Index i = c.nx - 1, jj = c.ny - 1;
      const double u_noise = std::sqrt(d.cov(d.w(i, jj), d.w(i, jj)));
      CHECK(j.u_w_um(i, jj) >= u_noise - 1e-12);
    }
    std::printf("joint vs dense, %dx%d grid, p %g/%g: max |difference| %.2e um, of u %.2e um\n",
                c.nx, c.ny, c.dx_mm / 5, c.dy_mm / 5, worst, worst_u);
  }
}

TEST_CASE("one axis: the joint estimate and its u equal a dense least-squares reference") {
  for (const int p : {1, 3}) {
    OneAxisTruth t;
    const auto tr = random_two_axis_truth(40 + static_cast<std::uint64_t>(p), 0.0);
    t.w_um = [tr](double x) { return tr.w_um(x, 20.0); };
    t.r_um = tr.r1x_um;
    t.m_um = [tr](double x) { return tr.ez_x_um(x, 0.0); };
    OneAxisSimOptions so;
    so.displacement_mm = 5.0 * p;
    so.workpiece_sensor.noise_sigma_um = so.reference_sensor.noise_sigma_um = 0.2;
    so.seed = 77 + static_cast<std::uint64_t>(p);
    const auto sim = simulate_one_axis(t, so);
    DisplacementOptions o;
    o.displacement_mm = 5.0 * p;
    o.chain_join = ChainJoin::given_initial_values;
    const auto j =
        separate_displacement_joint(sim.s1_1_um, sim.s2_1_um, sim.s2_2_um, sim.s1_2_um, o);
    REQUIRE(j.u_w_um.size() == sim.x_mm.size());
    // Dense: unknowns [r(x_p..x_{n-1+p}), m, w], readings S2_1, S2_2, S1_1, S1_2, all of σ.
    const Eigen::Index n = sim.x_mm.size();
    Eigen::MatrixXd a = Eigen::MatrixXd::Zero(4 * n, 3 * n);
    Eigen::VectorXd b(4 * n);
    for (Eigen::Index k = 0; k < n; ++k) {
      if (k >= p) a(k, k - p) = 1;  // Eq. (2)
      a(k, n + k) = 1;
      b(k) = sim.s2_1_um(k);
      a(n + k, k) = 1;  // Eq. (3): r(x_{k+p})
      a(n + k, n + k) = 1;
      b(n + k) = sim.s2_2_um(k);
      for (int s = 0; s < 2; ++s) {  // Eq. (1), both scans
        a((2 + s) * n + k, n + k) = 1;
        a((2 + s) * n + k, 2 * n + k) = 1;
        b((2 + s) * n + k) = s ? sim.s1_2_um(k) : sim.s1_1_um(k);
      }
    }
    const Eigen::VectorXd x = a.colPivHouseholderQr().solve(b);
    const Eigen::MatrixXd cov = (a.transpose() * a).inverse() * j.sigma_um * j.sigma_um;
    double worst = 0, worst_u = 0;
    for (Eigen::Index k = 0; k < n; ++k) {
      worst = std::max({worst, std::abs(j.estimate.m_um(k) - x(n + k)),
                        std::abs(j.estimate.w_um(k) - x(2 * n + k))});
      worst_u = std::max({worst_u, std::abs(j.u_m_um(k) - std::sqrt(cov(n + k, n + k))),
                          std::abs(j.u_w_um(k) - std::sqrt(cov(2 * n + k, 2 * n + k)))});
      if (k >= p) {
        worst = std::max(worst, std::abs(j.estimate.r_um(k) - x(k - p)));
        worst_u = std::max(worst_u, std::abs(j.u_r_um(k) - std::sqrt(cov(k - p, k - p))));
      }
    }
    INFO("p = " << p);
    CHECK(worst < 1e-9);
    CHECK(worst_u < 1e-9);
    // Equal to the paper's Eq. (9) for r and m (the method is exactly determined).
    const auto paper = separate_displacement(sim.s1_1_um, sim.s2_1_um, sim.s2_2_um, o);
    CHECK((paper.r_um - j.estimate.r_um).cwiseAbs().maxCoeff() < 1e-9);
    CHECK((paper.m_um - j.estimate.m_um).cwiseAbs().maxCoeff() < 1e-9);
  }
}

TEST_CASE("paper's noise on 25x25: joint estimate against the paper's row-by-row path") {
  // 24 random stages with roll and pitch up to 50 µrad, σ_se 0.16 µm, σ_sc 0.29 µm, rotation
  // correction on for both (the paper's Eqs. 22-27).  Errors in the gauge (truth moved by the
  // r_k(x_0) the method cannot see) and of w's shape (mean removed).
  constexpr int kSeeds = 24;
  struct Acc {
    double sum2 = 0, worst = 0, shape2 = 0;
    long n = 0;
    void add(const Eigen::MatrixXd& e, bool shape = false) {
      sum2 += e.squaredNorm();
      worst = std::max(worst, e.cwiseAbs().maxCoeff());
      n += e.size();
      if (shape) shape2 += (e.array() - e.mean()).square().sum();
    }
    double rms() const { return std::sqrt(sum2 / n); }
    double shape_rms() const { return std::sqrt(shape2 / n); }
  };
  Acc w[2], m_w[2], m2[2], r[2];
  int joint_better = 0;  // seeds where the joint w (shape) error is below the row-by-row one
  for (int s = 0; s < kSeeds; ++s) {
    const std::uint64_t seed = 1000 + static_cast<std::uint64_t>(s);
    TwoAxisSimOptions so;
    so.eddy_sensor.noise_sigma_um = kSigmaEddy;
    so.contact_sensor.noise_sigma_um = kSigmaContact;
    so.seed = seed;
    const auto truth = random_two_axis_truth(seed, 50.0);
    const auto sim = simulate_two_axis(truth, so);
    const auto gt = gauged_truth(truth, sim, so.geometry, true);
    double shape_rms[2];
    for (int q = 0; q < 2; ++q) {
      TwoAxisOptions o;
      o.rotation = RotationCorrection::on;
      o.solver = q == 0 ? TwoAxisSolver::joint : TwoAxisSolver::row_by_row;
      const auto res = separate_two_axis(sim.scan, o);
      w[q].add(res.w_um - gt.w, true);
      m_w[q].add(res.m_w_um - gt.m_w, true);
      m2[q].add(res.m2x_um - gt.m[1]);
      Eigen::MatrixXd er(25, 4);
      er.col(0) = res.r1x_um.col(0) - gt.r[0];
      er.col(1) = res.r2x_um.col(0) - gt.r[1];
      er.col(2) = res.r3y_um.row(0).transpose() - gt.r[2];
      er.col(3) = res.r4y_um.row(0).transpose() - gt.r[3];
      r[q].add(er);
      Eigen::ArrayXXd e = res.w_um - gt.w;
      shape_rms[q] = std::sqrt((e - e.mean()).square().mean());
    }
    joint_better += shape_rms[0] < shape_rms[1] ? 1 : 0;
  }
  std::printf(
      "25x25, sigma_se 0.16, sigma_sc 0.29 um, roll/pitch <= 50 urad, %d seeds (rms / worst, "
      "um):\n            joint               row-by-row\n",
      kSeeds);
  auto line = [](const char* name, const Acc& a, const Acc& b) {
    std::printf("  %-6s %7.3f / %7.3f   %7.3f / %7.3f\n", name, a.rms(), a.worst, b.rms(), b.worst);
  };
  line("w", w[0], w[1]);
  std::printf("  %-6s %7.3f             %7.3f   (w shape: mean removed)\n", "w-mean",
              w[0].shape_rms(), w[1].shape_rms());
  line("m_w", m_w[0], m_w[1]);
  line("m2x", m2[0], m2[1]);
  line("r", r[0], r[1]);
  std::printf("  joint w (shape) better than row by row in %d of %d seeds\n", joint_better, kSeeds);
  CHECK(w[0].rms() <= w[1].rms() / 3);
  CHECK(joint_better == kSeeds);
  CHECK(w[0].shape_rms() < w[1].shape_rms());
  CHECK(m2[0].rms() < m2[1].rms());
  CHECK(r[0].rms() < r[1].rms());
}

TEST_CASE("the joint fit's sigma_hat is the residual file's reference-piece sigma_hat") {
  // The residual file's reference family (Eq. 4 on every row minus its row mean) is the joint
  // estimate's residual: e = ∓(D − D̄)/2 per reading, so both σ̂ agree.
  TwoAxisSimOptions so;
  so.nx = 13;
  so.ny = 9;
  so.eddy_sensor.noise_sigma_um = kSigmaEddy;
  so.seed = 4;
  const auto sim = simulate_two_axis(random_two_axis_truth(4, 30.0), so);
  const auto j = separate_two_axis(sim.scan, TwoAxisOptions{});
  DisplacementResidualOptions ro;
  ro.whiteness.mc_samples = 99;
  ro.whiteness.alpha = 0.05;
  const auto res = displacement_residuals_two_axis({sim.scan}, ro);
  REQUIRE(!res.families.empty());
  REQUIRE(res.families[0].kind == RedundancyKind::reference_pieces);
  CHECK(res.families[0].dof == j.dof_reference);
  CHECK(std::abs(res.families[0].sigma_um - j.sigma_reference_um) < 1e-9);
}

TEST_CASE("figures of the paper that the physics does not give (README): Fig. 6 and sigma_mwxe") {
  // Fig. 6: "maximum error approximately 4 µm" of r at σ = 2 µm (section 2.3.1, Fig. 5 inputs,
  // 120 mm at 5 mm, d = 5 mm), noise on every reading.  Eq. (9) sums 24 differences of two
  // readings: the error at x_k has sd σ√(2k), 13.9 µm at the end, so a maximum of 4 µm is rare.
  constexpr int kRuns = 1000;
  std::vector<double> max_err;
  int at_most_4 = 0;
  for (int run = 0; run < kRuns; ++run) {
    OneAxisSimOptions so;
    so.workpiece_sensor.noise_sigma_um = so.reference_sensor.noise_sigma_um = 2.0;
    so.seed = 60000 + static_cast<std::uint64_t>(run);
    const auto sim = simulate_one_axis(haramiishi2024_fig5_truth(), so);
    const auto res = separate_displacement(sim.s1_1_um, sim.s2_1_um, sim.s2_2_um, {});
    max_err.push_back((res.r_um - sim.r_um).cwiseAbs().maxCoeff());
    at_most_4 += max_err.back() <= 4.0 ? 1 : 0;
  }
  std::sort(max_err.begin(), max_err.end());
  const double median = max_err[kRuns / 2];
  std::printf(
      "Fig. 6 (sigma 2 um per reading, %d runs): median max |r error| %.1f um, %.1f %% of "
      "runs at most 4 um\n",
      kRuns, median, 100.0 * at_most_4 / kRuns);
  CHECK(median > 10.0);
  CHECK(at_most_4 < kRuns / 20);

  // Table 2's σ_mwxe = 1.72 µm, "the mean of the standard deviation" of m_wxe (Eq. 24) over
  // repeated measurements, against what the sensors' noise alone gives (σ_se = 0.16 µm, 25 x 25,
  // the paper's 30/165 mm levers): row by row m_k(x_i) has variance σ²(1 + 2i), so m_wxe =
  // 5.5·(m2 − m1) has sd 5.5·σ·√(2(1 + 2i)), mean over the grid ≈ 5.9 µm.
  constexpr int kRepeats = 200;
  const auto truth = random_two_axis_truth(5, 30.0);
  Eigen::MatrixXd sum[2], sum2[2];
  double mean_u = 0;
  for (int q = 0; q < 2; ++q)
    sum[q] = sum2[q] = Eigen::MatrixXd::Zero(25, 25);
  for (int run = 0; run < kRepeats; ++run) {
    TwoAxisSimOptions so;
    so.eddy_sensor.noise_sigma_um = kSigmaEddy;
    so.contact_sensor.noise_sigma_um = kSigmaContact;
    so.seed = 70000 + static_cast<std::uint64_t>(run);
    const auto sim = simulate_two_axis(truth, so);
    for (int q = 0; q < 2; ++q) {
      TwoAxisOptions o;
      o.rotation = RotationCorrection::on;
      o.solver = q == 0 ? TwoAxisSolver::joint : TwoAxisSolver::row_by_row;
      const auto res = separate_two_axis(sim.scan, o);
      sum[q] += res.m_wxe_um;
      sum2[q] += res.m_wxe_um.cwiseProduct(res.m_wxe_um);
      if (q == 0) mean_u += res.u_m_wxe_um.mean() / kRepeats;
    }
  }
  double sd_mean[2];
  for (int q = 0; q < 2; ++q)
    sd_mean[q] =
        ((sum2[q] - sum[q].cwiseProduct(sum[q]) / kRepeats) / (kRepeats - 1)).cwiseSqrt().mean();
  double predicted = 0;
  for (int i = 0; i < 25; ++i)
    predicted += 5.5 * kSigmaEddy * std::sqrt(2.0 * (1 + 2 * i)) / 25;
  std::printf(
      "sigma_mwxe (mean sd over the grid, %d repeats, sigma_se 0.16 um): row by row %.2f "
      "um (propagation %.2f), joint %.2f um (its mean u %.2f); the paper's Table 2: "
      "1.72 um\n",
      kRepeats, sd_mean[1], predicted, sd_mean[0], mean_u);
  CHECK(std::abs(sd_mean[1] / predicted - 1) < 0.1);
  CHECK(std::abs(sd_mean[0] / mean_u - 1) < 0.1);
}

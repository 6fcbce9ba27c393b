// TikhonovSolver's shortcuts for a λ search against dense references: vᵀM⁻¹v from the fused
// forward substitution (factorize_and_quadratic_form), with and without a border and a penalty,
// and the selected inverse kept for the factorisation it belongs to (recomputed after the next
// factorisation, never stale).
#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdlib>

#include "errsep/core/tikhonov_solver.hpp"
#include "support/random_banded.hpp"

using namespace errsep::core;
using errsep::test::random_banded;

TEST_CASE("factorize_and_quadratic_form equals the dense v^T M^-1 v", "[tikhonov]") {
  const int m = 50, rows = 90;
  for (const int k : {0, 2, 4}) {
    for (const bool penalty : {false, true}) {
      INFO("border " << k << (penalty ? ", second-difference penalty" : ", identity"));
      const Eigen::SparseMatrix<double> A = random_banded(rows, m, k, 5, 11u + k);
      Eigen::MatrixXd Pd = Eigen::MatrixXd::Identity(m + k, m + k);
      if (penalty) {
        Pd.setZero();
        for (int i = 0; i + 2 < m; ++i) {
          Eigen::VectorXd l = Eigen::VectorXd::Zero(m + k);
          l(i) = 1;
          l(i + 1) = -2;
          l(i + 2) = 1;
          Pd += l * l.transpose();
        }
        Pd.diagonal().head(m).array() += 1e-3;
      }
      const Eigen::SparseMatrix<double> Ps = Pd.sparseView();
      TikhonovSolver solver(A, k, penalty ? Ps : Eigen::SparseMatrix<double>{});
      const Eigen::MatrixXd Ad = A;
      Eigen::VectorXd v(m + k);
      for (int i = 0; i < m + k; ++i)
        v(i) = std::sin(0.7 * i) + 0.1 * i;
      for (const double lambda : {0.1, 1.0, 5.0}) {
        double q = 0.0;
        REQUIRE(solver.factorize_and_quadratic_form(lambda, v, q) == SolverStatus::success);
        const Eigen::MatrixXd M = Ad.transpose() * Ad + lambda * lambda * Pd;
        const double ref = v.dot(M.ldlt().solve(v));
        CHECK(std::abs(q - ref) <= 1e-9 * std::abs(ref));
        CHECK(std::abs(solver.inverse_quadratic_form(v) - ref) <= 1e-9 * std::abs(ref));
        // The selected inverse of this factorisation, asked twice, and the next λ's.
        const Eigen::MatrixXd Z = M.inverse();
        for (int pass = 0; pass < 2; ++pass) {
          const SelectedInverse z = solver.selected_inverse();
          double worst = 0.0;
          for (int i = 0; i < m + k; ++i)
            for (int j = 0; j < m + k; ++j)
              if (i >= m || j >= m || std::abs(i - j) <= z.bandwidth)
                worst = std::max(worst, std::abs(z(i, j) - Z(i, j)));
          CHECK(worst <= 1e-9 * Z.cwiseAbs().maxCoeff());
        }
      }
      CHECK(solver.stats().selected_inversions == 3);  // once per factorisation
      double unused = 0.0;
      CHECK_THROWS_AS(solver.factorize_and_quadratic_form(1.0, Eigen::VectorXd::Ones(3), unused),
                      std::invalid_argument);
    }
  }
}

#pragma once
// Choice of the Tikhonov parameter λ by the L-curve criterion (Zhao 2019, after Eq. 17): the corner
// of maximum curvature of (log‖AX_λ − b‖, log‖X_λ‖).  The whole curve is returned, not only the
// corner, and a corner at the edge of the λ range is flagged rather than accepted silently.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "errsep/core/tikhonov_solver.hpp"

namespace errsep::core {

struct LCurvePoint {
  double lambda = 0;
  double residual_norm = 0;  ///< ‖A·X_λ − b‖
  double solution_norm = 0;  ///< ‖X_λ‖
  double curvature = 0;  ///< curvature of (log‖r‖, log‖X‖) at λ (closed form, see .cpp)
};

struct LCurveOptions {
  int count = 50;              ///< λ values on the log grid (>= 5)
  double lambda_min = 0.0;     ///< 0 = automatic: lambda_max · 10^-decades
  double lambda_max = 0.0;     ///< 0 = automatic: the bound of σ_max(A)
  double decades = 8.0;        ///< width of the automatic range
  int refine_iterations = 12;  ///< golden-section steps on the curvature around the grid maximum
  /// Threads for the grid sweep (each with its own CHOLMOD factor, TikhonovSolver::worker()).
  /// The grid points are independent, so 2 threads on 2 cores halve the sweep; the refinement
  /// after it is sequential.  Results do not depend on the number of threads.
  int threads = 1;
  /// An L-curve has a corner only if it has an L: a vertical branch on which the noise inflates
  /// the solution as λ falls.  The branch is measured as log10(‖X_λmin‖/‖X_corner‖); below this
  /// many decades the unregularised solution is not dominated by noise and there is no corner to
  /// take (0.05 decades: ‖X‖ grows by less than 12 %, i.e. the noise part of the unregularised
  /// solution is below about half of its size).  The paper's own system (weak curvature row) has
  /// a branch of 1.2 decades at σ = 0.1 µm; with the curvature fixed exactly, 0.001 to 0.05.
  double min_branch_decades = 0.05;
  bool is_valid(std::string* why = nullptr) const;
};

struct LCurveResult {
  std::vector<LCurvePoint> points;  ///< the grid, ascending λ (refined points not included)
  double lambda_corner = 0;  ///< λ of the largest interior curvature maximum (after refinement)
  double curvature_corner = 0;
  int corner_index = -1;  ///< grid index of the maximum before refinement
  bool at_edge = false;   ///< no interior maximum: the corner is the first or last grid point
  /// log10(‖X‖ at the smallest λ of the grid / ‖X‖ at the corner): the height of the vertical
  /// (noise) branch below the corner.
  double branch_decades = 0;
  /// False when the curve has no corner to take: the maximum is at the edge of the range, or
  /// the vertical branch is lower than LCurveOptions::min_branch_decades.
  bool has_corner = false;
  int factorizations = 0;
};

/// Curvature of the L-curve at the current factorisation of `solver` (λ = solver.lambda()), for the
/// solution x of right-hand side b (one extra solve).  Exposed for tests.
LCurvePoint lcurve_point(TikhonovSolver& solver, const Eigen::VectorXd& b,
                         const Eigen::VectorXd& x);

/// Sweeps λ over a log grid, computes the curve and its curvature, and refines the maximum.
/// Throws std::runtime_error if a factorisation fails (A rank-deficient and λ too small).
LCurveResult lcurve_corner(TikhonovSolver& solver, const Eigen::VectorXd& b,
                           const LCurveOptions& opts = {});

/// Discrepancy principle: the λ at which ‖A·X_λ − b‖ = target (bisection in log λ; ‖r‖ grows
/// monotonically with λ).  Returns the bracketing end if the target is outside the range.
double discrepancy_lambda(TikhonovSolver& solver, const Eigen::VectorXd& b, double target_norm,
                          double lambda_min, double lambda_max, int iterations = 30);

}  // namespace errsep::core

#include "errsep/core/lcurve.hpp"

#include <cmath>
#include <exception>
#include <memory>
#include <stdexcept>
#include <thread>
#include <vector>

namespace errsep::core {

bool LCurveOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (count < 5) return fail("count = " + std::to_string(count) + ": need at least 5 λ values");
  if (lambda_min < 0 || lambda_max < 0 || (lambda_max > 0 && lambda_min >= lambda_max))
    return fail("lambda range [" + std::to_string(lambda_min) + ", " + std::to_string(lambda_max) +
                "] is empty or negative");
  if (!(decades > 0)) return fail("decades = " + std::to_string(decades) + ": must be > 0");
  if (refine_iterations < 0) return fail("refine_iterations must be >= 0");
  if (!(min_branch_decades >= 0)) return fail("min_branch_decades must be >= 0");
  if (threads < 1 || threads > 64)
    return fail("threads = " + std::to_string(threads) + ": must be 1 to 64");
  return true;
}

namespace {
// Curvature of (½ log ρ, ½ log η) = (log‖r‖, log‖x‖) as a function of λ, using ρ' = −λ²η':
//   κ = −2ηρ/η' · (λ²η'ρ + 2ληρ + λ⁴ηη') / (λ⁴η² + ρ²)^{3/2}
// (derived from κ = (X'Y'' − X''Y')/(X'² + Y'²)^{3/2} with X = ½ln ρ, Y = ½ln η; η'' cancels).
// The form often quoted has λ²η² in the denominator and no leading minus: off by orders of
// magnitude, and its maximum lands on the opposite (concave) bend.  With this one the signed
// curvature is positive where the curve turns from its vertical (noise) branch to its horizontal
// (regularisation) branch, the corner; tests/core/tikhonov_lcurve.cpp checks it against finite
// differences.
LCurvePoint point_from_norms(double lambda, double rho, double eta, double deta) {
  const double l2 = lambda * lambda;
  const double num = l2 * deta * rho + 2.0 * lambda * eta * rho + l2 * l2 * eta * deta;
  const double den = std::pow(l2 * l2 * eta * eta + rho * rho, 1.5);
  LCurvePoint p;
  p.lambda = lambda;
  p.residual_norm = std::sqrt(rho);
  p.solution_norm = std::sqrt(eta);
  p.curvature = (deta != 0.0 && den > 0.0) ? -2.0 * eta * rho / deta * num / den : 0.0;
  return p;
}
}  // namespace

LCurvePoint lcurve_point(TikhonovSolver& solver, const Eigen::VectorXd& b,
                         const Eigen::VectorXd& x) {
  const double lambda = solver.lambda();
  const double rho = (solver.A() * x - b).squaredNorm();  // ρ = ‖r‖²
  // η = ‖Lx‖² = xᵀPx (P = I without a penalty); dx/dλ = −2λ(AᵀA + λ²P)⁻¹Px, hence
  // η' = dη/dλ = −4λ·(Px)ᵀ(AᵀA + λ²P)⁻¹(Px) (one extra solve).
  const Eigen::VectorXd Px = solver.apply_penalty(x);
  return point_from_norms(lambda, rho, x.dot(Px),
                          -4.0 * lambda * solver.inverse_quadratic_form(Px));
}

namespace {
// Atb = Aᵀb, formed once per sweep (it does not depend on λ; at N = 10⁶ the product costs as much
// as a solve).
LCurvePoint eval_at(TikhonovSolver& solver, const Eigen::VectorXd& b, const Eigen::VectorXd& Atb,
                    double lambda) {
  Eigen::VectorXd x;
  if (solver.factorize_and_solve(lambda, Atb, x) != SolverStatus::success)
    throw std::runtime_error("L-curve: " + solver.failure().message());
  // ρ = ‖Ax − b‖² without the product A·x (at N = 10⁶ it costs as much as a solve): since
  // (AᵀA + λ²I)x = Aᵀb, xᵀAᵀAx = xᵀAᵀb − λ²‖x‖², so ρ = bᵀb − xᵀAᵀb − λ²‖x‖².  Measured against
  // the direct residual: 3e-9 relative at N = 10⁵ over the grid.  Where the cancellation would
  // eat more than ~6 of the 16 digits (ρ < 1e-6·bᵀb) the residual is formed directly.
  const Eigen::VectorXd Px = solver.apply_penalty(x);
  const double eta = x.dot(Px);
  const double bb = b.squaredNorm();
  double rho = bb - x.dot(Atb) - lambda * lambda * eta;
  if (!(rho > 1e-6 * bb)) rho = (solver.A() * x - b).squaredNorm();
  return point_from_norms(lambda, rho, eta, -4.0 * lambda * solver.inverse_quadratic_form(Px));
}
}  // namespace

LCurveResult lcurve_corner(TikhonovSolver& solver, const Eigen::VectorXd& b,
                           const LCurveOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("L-curve options: " + why);
  const double lmax = opts.lambda_max > 0 ? opts.lambda_max : solver.sigma_max_bound();
  const double lmin = opts.lambda_min > 0 ? opts.lambda_min : lmax * std::pow(10.0, -opts.decades);
  LCurveResult res;
  const int before = solver.stats().factorizations;
  const Eigen::VectorXd Atb = solver.A().transpose() * b;
  const double lo = std::log(lmin), hi = std::log(lmax);
  auto grid_lambda = [&](int i) { return std::exp(lo + (hi - lo) * i / (opts.count - 1)); };
  res.points.resize(static_cast<std::size_t>(opts.count));
  const int threads = std::min(opts.threads, opts.count);
  int worker_factorizations = 0;
  if (threads <= 1) {
    for (int i = 0; i < opts.count; ++i)
      res.points[i] = eval_at(solver, b, Atb, grid_lambda(i));
  } else {
    // Thread t evaluates grid points t, t + T, …, each with its own factor; the points do not
    // interact, so the curve is the same as a sequential sweep's.
    std::vector<std::unique_ptr<TikhonovSolver>> workers;
    for (int t = 1; t < threads; ++t)
      workers.push_back(solver.worker());
    std::vector<std::exception_ptr> errors(static_cast<std::size_t>(threads));
    auto sweep = [&](int t, TikhonovSolver& s) {
      try {
        for (int i = t; i < opts.count; i += threads)
          res.points[i] = eval_at(s, b, Atb, grid_lambda(i));
      } catch (...) {
        errors[static_cast<std::size_t>(t)] = std::current_exception();
      }
    };
    std::vector<std::thread> pool;
    for (int t = 1; t < threads; ++t)
      pool.emplace_back(sweep, t, std::ref(*workers[t - 1]));
    sweep(0, solver);
    for (auto& th : pool)
      th.join();
    for (auto& e : errors)
      if (e) std::rethrow_exception(e);
    for (const auto& w : workers)
      worker_factorizations += w->stats().factorizations;
  }
  // The corner is the largest interior local maximum of positive curvature.  A maximum at the
  // range's edge is not a corner (the curve only keeps bending beyond the range): with a model
  // error in the data the global maximum can sit at the smallest λ, and taking it gave an
  // unregularised, meaningless solution.  Only when there is no interior maximum is the edge
  // taken, flagged as at_edge.
  int best = -1;
  for (int i = 1; i + 1 < opts.count; ++i) {
    const double k = res.points[i].curvature;
    if (k > 0 && k >= res.points[i - 1].curvature && k >= res.points[i + 1].curvature &&
        (best < 0 || k > res.points[best].curvature))
      best = i;
  }
  if (best < 0) {
    best = 0;
    for (int i = 1; i < opts.count; ++i)
      if (res.points[i].curvature > res.points[best].curvature) best = i;
  }
  res.corner_index = best;
  res.at_edge = best == 0 || best == opts.count - 1;
  res.lambda_corner = res.points[best].lambda;
  res.curvature_corner = res.points[best].curvature;

  if (!res.at_edge && opts.refine_iterations > 0) {
    // Golden-section search for the curvature maximum between the neighbouring grid points.
    const double g = 0.5 * (std::sqrt(5.0) - 1.0);
    double a = std::log(res.points[best - 1].lambda), c = std::log(res.points[best + 1].lambda);
    double x1 = c - g * (c - a), x2 = a + g * (c - a);
    double f1 = eval_at(solver, b, Atb, std::exp(x1)).curvature;
    double f2 = eval_at(solver, b, Atb, std::exp(x2)).curvature;
    for (int it = 0; it < opts.refine_iterations; ++it) {
      if (f1 > f2) {
        c = x2, x2 = x1, f2 = f1;
        x1 = c - g * (c - a);
        f1 = eval_at(solver, b, Atb, std::exp(x1)).curvature;
      } else {
        a = x1, x1 = x2, f1 = f2;
        x2 = a + g * (c - a);
        f2 = eval_at(solver, b, Atb, std::exp(x2)).curvature;
      }
    }
    const double xm = f1 > f2 ? x1 : x2;
    const double fm = std::max(f1, f2);
    if (fm > res.curvature_corner) {
      res.lambda_corner = std::exp(xm);
      res.curvature_corner = fm;
    }
  }
  res.branch_decades = std::log10(res.points.front().solution_norm /
                                  res.points[static_cast<std::size_t>(best)].solution_norm);
  res.has_corner = !res.at_edge && res.branch_decades >= opts.min_branch_decades;
  res.factorizations = solver.stats().factorizations - before + worker_factorizations;
  return res;
}

double discrepancy_lambda(TikhonovSolver& solver, const Eigen::VectorXd& b, double target_norm,
                          double lambda_min, double lambda_max, int iterations) {
  auto resid = [&](double lambda) {
    if (solver.factorize(lambda) != SolverStatus::success)
      throw std::runtime_error("discrepancy principle: " + solver.failure().message());
    return (solver.A() * solver.solve(b) - b).norm();
  };
  double lo = std::log(lambda_min), hi = std::log(lambda_max);
  if (resid(lambda_min) >= target_norm) return lambda_min;
  if (resid(lambda_max) <= target_norm) return lambda_max;
  for (int i = 0; i < iterations; ++i) {
    const double mid = 0.5 * (lo + hi);
    (resid(std::exp(mid)) < target_norm ? lo : hi) = mid;
  }
  return std::exp(0.5 * (lo + hi));
}

}  // namespace errsep::core

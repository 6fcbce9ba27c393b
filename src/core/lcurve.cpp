#include "errsep/core/lcurve.hpp"

#include <cmath>
#include <stdexcept>

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
  return true;
}

LCurvePoint lcurve_point(TikhonovSolver& solver, const Eigen::VectorXd& b,
                         const Eigen::VectorXd& x) {
  const double lambda = solver.lambda();
  const Eigen::VectorXd r = solver.A() * x - b;
  const double rho = r.squaredNorm();  // ρ = ‖r‖²
  const double eta = x.squaredNorm();  // η = ‖x‖²
  // dx/dλ = −2λ(AᵀA + λ²I)⁻¹x, hence η' = dη/dλ = −4λ·xᵀ(AᵀA + λ²I)⁻¹x (one extra solve).
  const Eigen::VectorXd y = solver.solve_normal(x);
  const double deta = -4.0 * lambda * x.dot(y);
  // Curvature of (½ log ρ, ½ log η) = (log‖r‖, log‖x‖) as a function of λ, using ρ' = −λ²η':
  //   κ = −2ηρ/η' · (λ²η'ρ + 2ληρ + λ⁴ηη') / (λ⁴η² + ρ²)^{3/2}
  // (derived from κ = (X'Y'' − X''Y')/(X'² + Y'²)^{3/2} with X = ½ln ρ, Y = ½ln η; η'' cancels).
  // The form often quoted has λ²η² in the denominator and no leading minus: off by orders of
  // magnitude, and its maximum lands on the opposite (concave) bend.  With this one the signed
  // curvature is positive where the curve turns from its vertical (noise) branch to its horizontal
  // (regularisation) branch, the corner; tests/core/tikhonov_lcurve.cpp checks it against finite
  // differences.
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

namespace {
LCurvePoint eval_at(TikhonovSolver& solver, const Eigen::VectorXd& b, double lambda) {
  if (solver.factorize(lambda) != SolverStatus::success)
    throw std::runtime_error("L-curve: factorisation of AᵀA + λ²I failed at λ = " +
                             std::to_string(lambda) + " (A rank-deficient?)");
  const Eigen::VectorXd x = solver.solve(b);
  return lcurve_point(solver, b, x);
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
  res.points.reserve(static_cast<std::size_t>(opts.count));
  const double lo = std::log(lmin), hi = std::log(lmax);
  for (int i = 0; i < opts.count; ++i) {
    const double lambda = std::exp(lo + (hi - lo) * i / (opts.count - 1));
    res.points.push_back(eval_at(solver, b, lambda));
  }
  int best = 0;
  for (int i = 1; i < opts.count; ++i)
    if (res.points[i].curvature > res.points[best].curvature) best = i;
  res.corner_index = best;
  res.at_edge = best == 0 || best == opts.count - 1;
  res.lambda_corner = res.points[best].lambda;
  res.curvature_corner = res.points[best].curvature;

  if (!res.at_edge && opts.refine_iterations > 0) {
    // Golden-section search for the curvature maximum between the neighbouring grid points.
    const double g = 0.5 * (std::sqrt(5.0) - 1.0);
    double a = std::log(res.points[best - 1].lambda), c = std::log(res.points[best + 1].lambda);
    double x1 = c - g * (c - a), x2 = a + g * (c - a);
    double f1 = eval_at(solver, b, std::exp(x1)).curvature;
    double f2 = eval_at(solver, b, std::exp(x2)).curvature;
    for (int it = 0; it < opts.refine_iterations; ++it) {
      if (f1 > f2) {
        c = x2, x2 = x1, f2 = f1;
        x1 = c - g * (c - a);
        f1 = eval_at(solver, b, std::exp(x1)).curvature;
      } else {
        a = x1, x1 = x2, f1 = f2;
        x2 = a + g * (c - a);
        f2 = eval_at(solver, b, std::exp(x2)).curvature;
      }
    }
    const double xm = f1 > f2 ? x1 : x2;
    const double fm = std::max(f1, f2);
    if (fm > res.curvature_corner) {
      res.lambda_corner = std::exp(xm);
      res.curvature_corner = fm;
    }
  }
  res.factorizations = solver.stats().factorizations - before;
  return res;
}

double discrepancy_lambda(TikhonovSolver& solver, const Eigen::VectorXd& b, double target_norm,
                          double lambda_min, double lambda_max, int iterations) {
  auto resid = [&](double lambda) {
    if (solver.factorize(lambda) != SolverStatus::success)
      throw std::runtime_error("discrepancy principle: factorisation failed at λ = " +
                               std::to_string(lambda));
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

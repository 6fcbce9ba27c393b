#include "errsep/core/four_sensor.hpp"

#include "four_sensor_paths.hpp"

#include <Eigen/Dense>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <stdexcept>

namespace errsep::core {

const char* to_string(LambdaRule r) {
  switch (r) {
    case LambdaRule::reml:
      return "reml";
    case LambdaRule::gcv:
      return "gcv";
    case LambdaRule::lcurve:
      return "lcurve";
    case LambdaRule::discrepancy:
      return "discrepancy";
    case LambdaRule::fixed:
      return "fixed";
    case LambdaRule::least_squares:
      return "least_squares";
  }
  return "unknown";
}

namespace {
constexpr LambdaRule kRules[] = {LambdaRule::reml,   LambdaRule::gcv,
                                 LambdaRule::lcurve, LambdaRule::discrepancy,
                                 LambdaRule::fixed,  LambdaRule::least_squares};
}

std::optional<LambdaRule> lambda_rule_from_string(std::string_view s) {
  if (s == "ls") return LambdaRule::least_squares;
  for (auto r : kRules)
    if (s == to_string(r)) return r;
  return std::nullopt;
}

std::vector<std::string> lambda_rule_names() {
  std::vector<std::string> out;
  for (auto r : kRules)
    out.emplace_back(to_string(r));
  return out;
}

const char* to_string(Estimator e) {
  switch (e) {
    case Estimator::posterior:
      return "posterior";
    case Estimator::paper_system:
      return "paper_system";
  }
  return "unknown";
}

std::optional<Estimator> estimator_from_string(std::string_view s) {
  for (auto e : {Estimator::posterior, Estimator::paper_system})
    if (s == to_string(e)) return e;
  return std::nullopt;
}

bool LambdaSearchOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (count < 3) return fail("search.count = " + std::to_string(count) + ": need at least 3");
  if (!(decades_below >= 0 && decades_above >= 0 && decades_below + decades_above > 0))
    return fail("search range decades must be >= 0 and not both 0");
  if (refine_iterations < 0) return fail("search.refine_iterations must be >= 0");
  if (threads < 1 || threads > 64)
    return fail("search.threads = " + std::to_string(threads) + ": must be 1 to 64");
  return true;
}

const char* to_string(LambdaFallback f) {
  switch (f) {
    case LambdaFallback::none:
      return "none";
    case LambdaFallback::no_regularisation:
      return "no_regularisation";
    case LambdaFallback::discrepancy:
      return "discrepancy";
    case LambdaFallback::collapse_least_squares:
      return "collapse_least_squares";
  }
  return "unknown";
}

bool FourSensorOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (rule == LambdaRule::fixed && !(fixed_lambda >= 0 && std::isfinite(fixed_lambda)))
    return fail("fixed_lambda = " + std::to_string(fixed_lambda) + ": must be finite and >= 0");
  if (!(discrepancy_tau > 0)) return fail("discrepancy_tau must be > 0");
  if (iterated_refinements < 0 || iterated_refinements > 100)
    return fail("iterated_refinements = " + std::to_string(iterated_refinements) +
                ": must be in [0, 100]");
  if (uncertainty_probes < 1) return fail("uncertainty_probes must be >= 1");
  if (!(collapse_edf >= 0)) return fail("collapse_edf must be >= 0");
  if (estimator == Estimator::paper_system && (rule == LambdaRule::reml || rule == LambdaRule::gcv))
    return fail(std::string("rule ") + to_string(rule) +
                " needs estimator posterior (the paper's system has correlated rows)");
  if (estimator == Estimator::posterior) {
    if (gauge != CurvatureGauge::reference_without_curvature)
      return fail(std::string("gauge ") + to_string(gauge) +
                  " needs estimator paper_system (the posterior fixes the bow of f exactly)");
    if (motion != MotionEstimator::all_configurations)
      return fail("motion paper_eq18_19 needs estimator paper_system");
    if (iterated_refinements != 0) return fail("iterated_refinements needs estimator paper_system");
  }
  return search.is_valid(why) && lcurve.is_valid(why);
}

namespace {

// Everything after the factorisation that is linear in the outputs m: solve, refine, gauge, and
// the S/γ estimate.  Used once for the data and again for each uncertainty probe.
struct Pipeline {
  const FourSensorConfig& cfg;
  const FourSensorOptions& opts;
  TikhonovSolver& solver;
  Eigen::Matrix4d C;
  Eigen::Matrix<double, 4, 2> C23;  // columns 2 and 3 of C (e_2, e_3 with e_1 = e_4 = 0)
  std::array<int, 4> k;
  std::array<double, 4> O_mm;

  Eigen::VectorXd solve_X(const Eigen::VectorXd& b) const {
    Eigen::VectorXd X = solver.solve(b);
    for (int i = 0; i < opts.iterated_refinements; ++i)
      X += solver.solve(b - solver.A() * X);
    apply_gauge(cfg, opts.gauge, X);
    return X;
  }

  struct Motion {
    Eigen::VectorXd S, gamma_rad;
    Eigen::Vector4d e;
    Eigen::MatrixXd resid;
  };

  Motion motion(const Eigen::MatrixXd& m, const Eigen::VectorXd& X) const {
    const int N = cfg.N, P = cfg.positions();
    Motion out;
    out.S.resize(P);
    out.gamma_rad.resize(P);
    out.resid.resize(P, 4);
    // ê from Δe = C·e with e_1 = 0 and e_4 = 0 (the constant of γ, as Eq. 19 leaves it).
    const Eigen::Vector4d de = X.tail<4>();
    const Eigen::Vector2d e23 = C23.colPivHouseholderQr().solve(de);
    out.e << 0.0, e23(0), e23(1), 0.0;
    // Least-squares line S + O·γ through four points: precomputed normal equations.
    double so = 0, soo = 0;
    for (double o : O_mm)
      so += o, soo += o * o;
    const double det = 4.0 * soo - so * so;
    for (int n = 0; n < P; ++n) {
      Eigen::Vector4d r;
      for (int j = 0; j < 4; ++j)
        r(j) = m(n, j) - X(n + k[j]) - out.e(j);
      double S, g_um_per_mm;
      if (opts.motion == MotionEstimator::paper_eq18_19) {
        S = m(n, 0) - X(n);                                                  // Eq. (18)
        g_um_per_mm = (m(n, 3) - m(n, 0) - (X(n + k[3]) - X(n))) / O_mm[3];  // Eq. (19), no e_4
      } else {
        double sr = 0, sor = 0;
        for (int j = 0; j < 4; ++j)
          sr += r(j), sor += O_mm[j] * r(j);
        S = (soo * sr - so * sor) / det;
        g_um_per_mm = (4.0 * sor - so * sr) / det;
      }
      out.S(n) = S;
      out.gamma_rad(n) = g_um_per_mm * 1e-3;  // µm/mm = mrad
      for (int j = 0; j < 4; ++j)
        out.resid(n, j) = r(j) - S - O_mm[j] * g_um_per_mm;
    }
    (void)N;
    return out;
  }
};

}  // namespace

std::string FourSensorResult::brief_report() const {
  char buf[768];
  std::snprintf(buf, sizeof buf,
                "four-sensor N=%d P=%d s=(%d,%d,%d) dx=%.4g mm: %s, prior %s, lambda=%.4g (%s%s%s) "
                "edf_f=%.3g |AX-b|=%.4g |LX|=%.4g sigma_hat=%.3g um (dof %d) factorizations=%d "
                "time=%.3f s",
                config.N, config.positions(), config.s2, config.s3, config.s4, config.dx_mm,
                to_string(estimator), to_string(penalty), lambda, to_string(rule),
                lambda_fallback == LambdaFallback::discrepancy
                    ? ", no L-curve corner: discrepancy principle used"
                : lambda_fallback == LambdaFallback::no_regularisation
                    ? ", no L-curve corner: not noise-dominated, no regularisation"
                : lambda_fallback == LambdaFallback::collapse_least_squares
                    ? ", COLLAPSE: the prior swallowed f; unregularised separation reported"
                    : "",
                lambda_at_refused_edge
                    ? ", minimum not bracketed: the lambda beyond it were refused"
                : lambda_at_edge ? ", at the edge of the range"
                                 : "",
                edf_f, residual_norm, solution_norm, sigma_um, redundancy_dof,
                solver_stats.factorizations, total_s);
  std::string out = buf;
  if (!lambda_rejected.empty())
    out += " (" + std::to_string(lambda_rejected.size()) +
           " lambda rejected: factor not positive definite)";
  return out;
}

namespace {

FourSensorResult separate(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                          const Eigen::MatrixXd* g_um, const FourSensorOptions& opts) {
  const auto t0 = std::chrono::steady_clock::now();
  std::string why;
  if (!cfg.is_valid(&why)) throw std::invalid_argument("invalid configuration: " + why);
  if (!opts.is_valid(&why)) throw std::invalid_argument("invalid options: " + why);
  if (!m_um.allFinite()) throw std::invalid_argument("sensor outputs contain non-finite values");
  if (g_um && !g_um->allFinite())
    throw std::invalid_argument("combined outputs contain non-finite values");

  AugmentedSystem sys = assemble_four_sensor_system(cfg, m_um, opts.gauge, opts.weighting);
  if (g_um) sys.b = right_hand_side_combined(cfg, *g_um, opts.gauge, opts.weighting);
  // A moves into the solver (solver.A() from here on); the border: Δe, the last 4 unknowns (Eq. 7).
  TikhonovSolver solver(std::move(sys.A), 4);
  Pipeline pipe{
      cfg, opts, solver, combination_matrix(cfg), {}, cfg.offsets_samples(), cfg.offsets_mm()};
  pipe.C23 = pipe.C.middleCols<2>(1);
  const int N = cfg.N, P = cfg.positions();

  FourSensorResult res;
  res.config = cfg;
  res.rule = opts.rule;
  res.estimator = Estimator::paper_system;
  res.penalty = Penalty::identity;
  res.gauge = opts.gauge;

  // With the exact gauge A has the known 3-dimensional null space, so "λ = 0" means the smallest
  // λ that keeps AᵀA + λ²I factorisable; the null-space part it leaves is zero anyway (Aᵀb is
  // orthogonal to it) and apply_gauge() sets it.
  const double lambda_floor = opts.gauge == CurvatureGauge::reference_without_curvature
                                  ? 1e-7 * solver.sigma_max_bound()
                                  : 0.0;
  auto floor_lambda = [&](double l) { return std::max(l, lambda_floor); };

  // Noise level from the redundancy: the unregularised fit leaves 4P readings explained by
  // N + 2P − 1 identifiable parameters (f, S, γ, e less the 4 gauge directions), so
  // σ̂² = RSS / (2P − N + 1).
  if (solver.factorize(floor_lambda(0.0)) != SolverStatus::success)
    throw std::runtime_error(
        "the augmented matrix A is rank-deficient beyond the known null space (spacings s = (" +
        std::to_string(cfg.s2) + ", " + std::to_string(cfg.s3) + ", " + std::to_string(cfg.s4) +
        ") with N = " + std::to_string(N) + "): " + solver.failure().message());
  {
    FourSensorOptions ls_opts = opts;
    ls_opts.iterated_refinements = 0;
    Pipeline ls{cfg, ls_opts, solver, pipe.C, pipe.C23, pipe.k, pipe.O_mm};
    const Eigen::VectorXd X_ls = ls.solve_X(sys.b);
    const auto mo = ls.motion(m_um, X_ls);
    res.redundancy_dof = 2 * P - N + 1;
    res.sigma_um = std::sqrt(mo.resid.squaredNorm() / std::max(1, res.redundancy_dof));
  }

  const double lmax =
      opts.lcurve.lambda_max > 0 ? opts.lcurve.lambda_max : solver.sigma_max_bound();
  const double lmin = opts.lcurve.lambda_min > 0 ? opts.lcurve.lambda_min
                                                 : lmax * std::pow(10.0, -opts.lcurve.decades);
  int worker_factorizations = 0;
  auto discrepancy = [&] {
    // δ = expected norm of the noise in b: b₀ = C·m per position, so E‖noise‖² = σ²·P·‖C‖_F².
    const double per_pos = opts.weighting == RowWeighting::paper ? pipe.C.squaredNorm() : 2.0;
    const double delta = res.sigma_um * std::sqrt(P * per_pos);
    return discrepancy_lambda(solver, sys.b, opts.discrepancy_tau * delta, lmin, lmax);
  };
  switch (opts.rule) {
    case LambdaRule::lcurve: {
      const int own_before = solver.stats().factorizations;
      res.lcurve = lcurve_corner(solver, sys.b, opts.lcurve);
      // Factorisations done by the sweep's worker threads (not in solver.stats()).
      worker_factorizations =
          res.lcurve.factorizations - (solver.stats().factorizations - own_before);
    }
      res.lambda = res.lcurve.lambda_corner;
      // No corner: the maximum is at the edge of the range (the curve keeps bending past it), or
      // the curve has no vertical branch (the unregularised solution is not noise-dominated).
      // With the curvature fixed exactly there is then nothing to regularise; with a weak
      // curvature row a small λ would leave the nearly null bow free (Fig. 3(d)), so λ comes from
      // the discrepancy principle.  Either way the result says so.
      if (!res.lcurve.has_corner) {
        if (opts.gauge == CurvatureGauge::reference_without_curvature) {
          res.lambda = 0.0;  // raised to lambda_floor below
          res.lambda_fallback = LambdaFallback::no_regularisation;
        } else {
          res.lambda = discrepancy();
          res.lambda_fallback = LambdaFallback::discrepancy;
        }
      }
      break;
    case LambdaRule::discrepancy:
      res.lambda = discrepancy();
      break;
    case LambdaRule::fixed:
      res.lambda = opts.fixed_lambda;
      break;
    case LambdaRule::least_squares:
      res.lambda = 0.0;
      break;
    case LambdaRule::reml:
    case LambdaRule::gcv:
      throw std::invalid_argument("rule reml/gcv needs estimator posterior");  // is_valid refuses
  }
  res.lambda = floor_lambda(res.lambda);
  if (solver.factorize(res.lambda) != SolverStatus::success)
    throw std::runtime_error("factorisation failed at the chosen " + solver.failure().message());
  const Eigen::VectorXd X = pipe.solve_X(sys.b);
  res.residual_norm = (solver.A() * X - sys.b).norm();
  res.solution_norm = X.norm();
  res.f_um = X.head(N);
  res.delta_e_um = X.tail<4>();
  res.f_x_mm = Eigen::VectorXd::LinSpaced(N, 0.0, (N - 1) * cfg.dx_mm);
  res.x_mm = res.f_x_mm.head(P);
  auto mo = pipe.motion(m_um, X);
  res.S_um = std::move(mo.S);
  res.gamma_rad = std::move(mo.gamma_rad);
  res.e_um = mo.e;
  res.sensor_residual_um = std::move(mo.resid);

  if (opts.compute_uncertainty) {
    // The whole pipeline is linear in m for a fixed λ, so u² = σ̂²·Σ_k (∂·/∂m_k)²: exact with the
    // 4P unit vectors when that is small, else a Rademacher estimate of the diagonal of J·Jᵀ.
    res.u_S_um = Eigen::VectorXd::Zero(P);
    res.u_gamma_rad = Eigen::VectorXd::Zero(P);
    res.u_f_um = Eigen::VectorXd::Zero(N);
    const int total = 4 * P;
    const bool exact = total <= 4 * std::max(opts.uncertainty_probes, 100);
    const int probes = exact ? total : opts.uncertainty_probes;
    std::mt19937_64 rng(12345);
    std::bernoulli_distribution coin(0.5);
    Eigen::MatrixXd v(P, 4);
    for (int p = 0; p < probes; ++p) {
      if (exact) {
        v.setZero();
        v(p / 4, p % 4) = 1.0;
      } else {
        for (int i = 0; i < P; ++i)
          for (int j = 0; j < 4; ++j)
            v(i, j) = coin(rng) ? 1.0 : -1.0;
      }
      const Eigen::VectorXd Xv = pipe.solve_X(right_hand_side(cfg, v, opts.gauge, opts.weighting));
      const auto mv = pipe.motion(v, Xv);
      res.u_S_um.array() += mv.S.array().square();
      res.u_gamma_rad.array() += mv.gamma_rad.array().square();
      res.u_f_um.array() += Xv.head(N).array().square();
    }
    const double scale = res.sigma_um * res.sigma_um / (exact ? 1.0 : probes);
    res.u_S_um = (res.u_S_um * scale).cwiseSqrt();
    res.u_gamma_rad = (res.u_gamma_rad * scale).cwiseSqrt();
    res.u_f_um = (res.u_f_um * scale).cwiseSqrt();
  }
  res.solver_stats = solver.stats();
  res.solver_stats.factorizations += worker_factorizations;
  res.total_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

}  // namespace

FourSensorOptions options_for_gauge(CurvatureGauge gauge) {
  FourSensorOptions opts;
  opts.gauge = gauge;
  if (gauge != CurvatureGauge::reference_without_curvature) {
    opts.estimator = Estimator::paper_system;
    opts.rule = LambdaRule::lcurve;
  }
  return opts;
}

FourSensorResult separate_four_sensor(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                                      const FourSensorOptions& opts) {
  if (opts.estimator == Estimator::posterior) {
    std::string why;
    if (!cfg.is_valid(&why)) throw std::invalid_argument("invalid configuration: " + why);
    if (!opts.is_valid(&why)) throw std::invalid_argument("invalid options: " + why);
    if (!m_um.allFinite()) throw std::invalid_argument("sensor outputs contain non-finite values");
    return separate_posterior(cfg, m_um, opts);
  }
  return separate(cfg, m_um, nullptr, opts);
}

FourSensorResult separate_four_sensor_combined(const FourSensorConfig& cfg,
                                               const Eigen::MatrixXd& m_um,
                                               const Eigen::MatrixXd& g_um,
                                               const FourSensorOptions& opts) {
  if (opts.estimator != Estimator::paper_system)
    throw std::invalid_argument(
        "separate_four_sensor_combined: measured combined outputs need estimator paper_system");
  return separate(cfg, m_um, &g_um, opts);
}

}  // namespace errsep::core

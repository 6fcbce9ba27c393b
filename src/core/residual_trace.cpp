#include "errsep/core/residual_trace.hpp"

#include "errsep/core/step_decision.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <stdexcept>

namespace errsep::core {

namespace {

double legendre(int k, double u) {
  double p0 = 1.0, p1 = u;
  if (k == 0) return p0;
  for (int j = 2; j <= k; ++j) {
    const double p2 = ((2.0 * j - 1.0) * u * p1 - (j - 1.0) * p0) / j;
    p0 = p1;
    p1 = p2;
  }
  return p1;
}

// The F-test of reading-space columns Z (4P × k, row 4n + i) against the model: projected,
// column-normalised, directions below 1e-6 of a column's norm dropped (as ResidualSpace::add).
struct Nested {
  int identifiable = 0;
  double delta_rss = 0, F = 0, p = 1;
  Eigen::VectorXd beta;  // least-squares coefficients of Z's columns (minimum norm)
};
// The F test of columns already projected off the model (Zp, their unprojected norms D) on the
// residual r with dof degrees of freedom.
Nested projected_test(Eigen::MatrixXd Zp, const Eigen::VectorXd& D, const Eigen::VectorXd& r,
                      int dof) {
  Nested out;
  out.beta = Eigen::VectorXd::Zero(Zp.cols());
  if (Zp.cols() == 0) return out;
  for (Eigen::Index c = 0; c < Zp.cols(); ++c)
    if (D(c) > 0) Zp.col(c) /= D(c);
  Eigen::BDCSVD<Eigen::MatrixXd> svd(Zp, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::VectorXd& sv = svd.singularValues();
  int k = 0;
  for (Eigen::Index j = 0; j < sv.size(); ++j)
    if (sv(j) > 1e-6) ++k;
  out.identifiable = k;
  if (k == 0 || dof - k <= 0) return out;
  const Eigen::VectorXd c = svd.matrixU().leftCols(k).transpose() * r;
  out.delta_rss = c.squaredNorm();
  const double rest = r.squaredNorm() - out.delta_rss;
  out.F = rest > 0 ? (out.delta_rss / k) / (rest / (dof - k)) : 0.0;
  out.p = f_test_p_value(out.F, k, dof - k);
  const Eigen::VectorXd bt = svd.matrixV().leftCols(k) * (c.array() / sv.head(k).array()).matrix();
  for (Eigen::Index j = 0; j < Zp.cols(); ++j)
    out.beta(j) = D(j) > 0 ? bt(j) / D(j) : 0.0;
  return out;
}

Nested nested_test(const ResidualSpace& space, const Eigen::VectorXd& r, const Eigen::MatrixXd& Z) {
  if (Z.cols() == 0) return projected_test(Eigen::MatrixXd(0, 0), Eigen::VectorXd(), r, 0);
  const Eigen::MatrixXd Zr = reduce_columns(space.config(), Z);
  return projected_test(space.project_out(Zr), Zr.colwise().norm().transpose(), r, space.dof());
}

// Each test's p-value times the number of tests run (at most 1), and which are significant.
void bonferroni(ResidualTrace& out, double alpha) {
  for (const auto& d : out.tests)
    if (d.tested) ++out.tests_run;
  for (auto& d : out.tests) {
    if (!d.tested) continue;
    d.p_adjusted = std::min(1.0, d.p_value * out.tests_run);
    out.p_value = std::min(out.p_value, d.p_adjusted);
    d.significant = d.p_adjusted < alpha;
  }
}

// The polynomial test of one variable: DependenceTest from projected_test's figures.
DependenceTest dependence_test(const std::string& name, const Nested& nt, int parameters, int dof) {
  DependenceTest d;
  d.variable = name;
  d.parameters = parameters;
  if (parameters == 0) {
    d.not_tested = "constant or not recorded";
    return d;
  }
  d.identifiable = nt.identifiable;
  if (nt.identifiable == 0 || dof - nt.identifiable <= 0) {
    d.not_tested = "the model already holds every such function";
    return d;
  }
  d.tested = true;
  d.statistic = nt.F;
  d.p_value = nt.p;
  d.coefficients_um = nt.beta;
  return d;
}

// Legendre columns P_1..P_d of v scaled to [−1, 1] over the readings selected by `config`
// (0..3, or −1 for all, one common set of columns).
Eigen::MatrixXd legendre_columns(const Eigen::MatrixXd& v, int degree, int config, int first,
                                 double* lo_out = nullptr, double* hi_out = nullptr) {
  const Eigen::Index P = v.rows();
  double lo = 0, hi = 0;
  if (config < 0) {
    lo = v.minCoeff();
    hi = v.maxCoeff();
  } else {
    lo = v.col(config).minCoeff();
    hi = v.col(config).maxCoeff();
  }
  if (lo_out) *lo_out = lo;
  if (hi_out) *hi_out = hi;
  const int k = degree - first + 1;
  Eigen::MatrixXd Z = Eigen::MatrixXd::Zero(4 * P, std::max(0, k));
  if (!(hi > lo) || k <= 0) return Eigen::MatrixXd(4 * P, 0);
  const double mid = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
  for (Eigen::Index n = 0; n < P; ++n)
    for (int i = 0; i < 4; ++i) {
      if (config >= 0 && i != config) continue;
      const double u = (v(n, i) - mid) / half;
      for (int d = first; d <= degree; ++d)
        Z(4 * n + i, d - first) = legendre(d, u);
    }
  return Z;
}

std::string fmt(const char* f, double a, double b = 0, double c = 0, double d = 0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, f, a, b, c, d);
  return buf;
}

// Largest ratio of a configuration's residual energy to its expectation, relative to the whole:
// max_c (Σ_n r_nc²/Σ_n d_nc)/(Σ r²/Σ d).
double configuration_statistic(const Eigen::MatrixXd& res, const Eigen::Vector4d& dsum,
                               int* which = nullptr) {
  const double total = res.squaredNorm() / dsum.sum();
  double best = 0;
  for (int c = 0; c < 4; ++c) {
    if (!(dsum(c) > 1e-9)) continue;
    const double v = res.col(c).squaredNorm() / dsum(c) / total;
    if (v > best) {
      best = v;
      if (which) *which = c;
    }
  }
  return best;
}

}  // namespace

bool ResidualTraceOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(alpha > 0 && alpha < 1))
    return fail("alpha = " + std::to_string(alpha) + ": must be in (0, 1)");
  if (time_degree < 1 || position_degree < 1 || level_degree < 2 || temperature_degree < 1)
    return fail("degrees must be >= 1 (level_degree >= 2: a non-linearity is of degree 2)");
  if (mc_samples < 19)
    return fail("mc_samples = " + std::to_string(mc_samples) + ": must be >= 19");
  return true;
}

Eigen::MatrixXd reading_projector_diagonal(const ResidualSpace& space) {
  const FourSensorConfig& cfg = space.config();
  const int P = cfg.positions();
  const auto V = residual_basis(cfg);
  const Eigen::MatrixXd& Q = space.basis();
  Eigen::MatrixXd d(P, 4);
  for (int n = 0; n < P; ++n)
    for (int i = 0; i < 4; ++i) {
      const Eigen::Vector2d v = V.row(i).transpose();
      d(n, i) =
          std::max(0.0, v.squaredNorm() - (Q.middleRows<2>(2 * n).transpose() * v).squaredNorm());
    }
  return d;
}

std::string ResidualTrace::brief_report() const {
  std::string out =
      fmt("residual trace: %d tests, smallest adjusted p = %.3g: ", tests_run, p_value);
  if (!depends) return out + "no dependence on a recorded variable";
  for (std::size_t j = 0; j < findings.size(); ++j)
    out += (j ? "; " : "") + findings[j];
  return out;
}

ResidualTrace trace_residual(const ResidualSpace& space, const Eigen::MatrixXd& m_um,
                             const RecordedVariables& rec, const ResidualTraceOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("invalid residual trace options: " + why);
  const FourSensorConfig& cfg = space.config();
  const int P = cfg.positions();
  if (m_um.rows() != P || m_um.cols() != 4)
    throw std::invalid_argument("trace_residual: readings must be P x 4");
  auto check = [&](const Eigen::MatrixXd& v, const char* name) {
    if (v.size() != 0 && (v.rows() != P || v.cols() != 4 || !v.allFinite()))
      throw std::invalid_argument(std::string("trace_residual: ") + name +
                                  " must be a finite P x 4 matrix like the readings");
  };
  check(rec.t_s, "t_s");
  check(rec.direction, "direction");
  check(rec.temperature_C, "temperature_C");
  const Eigen::MatrixXd t = rec.t_s.size() == 0 ? scan_order_times_s(cfg) : rec.t_s;

  ResidualTrace out;
  out.alpha = opts.alpha;
  const Eigen::VectorXd r = space.project_out(reduce_readings(cfg, m_um));
  const int dof = space.dof();
  auto polynomial_test = [&](const std::string& name, const Eigen::MatrixXd& Z) {
    return dependence_test(name, nested_test(space, r, Z), static_cast<int>(Z.cols()), dof);
  };

  Eigen::MatrixXd x(P, 4);
  for (int n = 0; n < P; ++n)
    x.row(n).setConstant(n * cfg.dx_mm);
  out.tests.push_back(polynomial_test("time", legendre_columns(t, opts.time_degree, -1, 1)));
  {
    Eigen::MatrixXd Z(4 * P, 0);
    for (int c = 0; c < 4; ++c) {
      const Eigen::MatrixXd Zc = legendre_columns(x, opts.position_degree, c, 1);
      Eigen::MatrixXd Zn(4 * P, Z.cols() + Zc.cols());
      Zn << Z, Zc;
      Z = std::move(Zn);
    }
    out.tests.push_back(polynomial_test("position (per configuration)", Z));
  }
  {
    // Configuration: Monte-Carlo calibrated (see the file comment).
    DependenceTest d;
    d.variable = "configuration";
    const Eigen::MatrixXd dg = reading_projector_diagonal(space);
    const Eigen::Vector4d dsum = dg.colwise().sum().transpose();
    if (dof > 0 && r.squaredNorm() > 0) {
      d.tested = true;
      d.parameters = 4;
      d.identifiable = 3;
      int which = 0;
      d.statistic = configuration_statistic(expand_residual(cfg, r), dsum, &which);
      std::mt19937_64 rng(opts.seed);
      std::normal_distribution<double> g(0.0, 1.0);
      Eigen::MatrixXd Zd(2 * P, opts.mc_samples);
      for (Eigen::Index j = 0; j < Zd.size(); ++j)
        Zd.data()[j] = g(rng);
      const Eigen::MatrixXd R = space.project_out(Zd);
      int ge = 0;
      for (int s = 0; s < opts.mc_samples; ++s)
        if (configuration_statistic(expand_residual(cfg, R.col(s)), dsum) >= d.statistic) ++ge;
      d.p_value = (1.0 + ge) / (1.0 + opts.mc_samples);
      d.coefficients_um = Eigen::VectorXd::Constant(1, which + 1.0);  // the configuration (1-based)
    } else {
      d.not_tested = "no redundancy";
    }
    out.tests.push_back(d);
  }
  {
    // Reading level.  The fitted readings r̂ = m − (reading-space residual) carry the noise Hε,
    // which is independent of the residual Πε under Gaussian noise (orthogonal projections), so
    // columns built from r̂ give exact F tests; columns of m itself would correlate with the
    // residual at order σ/range.
    const Eigen::MatrixXd fit = m_um - expand_residual(cfg, r);
    const double lo = fit.minCoeff(), hi = fit.maxCoeff();
    const double mid = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
    // Common to every configuration: one sensor moved to four places reads through one
    // characteristic m = r + c₂·a² + c₃·a³, a = r − mid (its gain c₁ scales f, S, γ and e alike
    // and is not identifiable).  The score test of c₂ (and of c₃) is the F test of the one column
    // ∂m/∂c = a² (a³) at r̂: the non-linearity's own signature, one degree of freedom, the most
    // powerful test against that alternative.  What the model absorbs of it (a function of f's
    // sample, the parts affine in the offset O per position) cannot be seen; the rest is mostly
    // the cross term 2c₂·(f(x + D_i) − mid)·(S(x) + O_i·γ(x)) (see the file comment).
    for (int power : {2, 3}) {
      Eigen::MatrixXd Z(4 * P, half > 0 ? 1 : 0);
      if (half > 0)
        for (int n = 0; n < P; ++n)
          for (int i = 0; i < 4; ++i)
            Z(4 * n + i, 0) = std::pow(fit(n, i) - mid, power);
      DependenceTest d = polynomial_test(power == 2 ? "reading level (quadratic non-linearity)"
                                                    : "reading level (cubic non-linearity)",
                                         Z);
      d.range_lo_um = lo;
      d.range_hi_um = hi;
      if (d.tested) {
        const Eigen::VectorXd zp = space.project_out(reduce_columns(cfg, Z)).col(0);
        const double explained = std::pow(zp.dot(r), 2) / zp.squaredNorm();
        const double s2 = (r.squaredNorm() - explained) / std::max(1, dof - 1);
        const double c = d.coefficients_um(0), u = std::sqrt(s2) / zp.norm();
        d.nonlinear_um = std::abs(c) * std::pow(half, power);
        d.visible_fraction = zp.norm() / Z.col(0).norm();
        if (power == 2) {
          d.kappa_per_um = c;
          d.u_kappa_per_um = u;
        } else {
          d.kappa3_per_um2 = c;
          d.u_kappa3_per_um2 = u;
        }
      }
      out.tests.push_back(d);
    }
    // Per configuration (degree 1 and up: a configuration's gain is the library's gain effect).
    for (int c = 0; c < 4; ++c) {
      double a = 0, b = 0;
      DependenceTest dc = polynomial_test("reading level of configuration " + std::to_string(c + 1),
                                          legendre_columns(fit, opts.level_degree, c, 1, &a, &b));
      dc.range_lo_um = a;
      dc.range_hi_um = b;
      if (dc.tested && dc.coefficients_um.size() > 0) {
        const double h = 0.5 * (b - a);
        // Quadratic coefficient in m: P_2(u) = (3u² − 1)/2 gives 1.5·c_2/h²; P_3 has no u² term.
        if (dc.coefficients_um.size() > 1) dc.kappa_per_um = 1.5 * dc.coefficients_um(1) / (h * h);
        double worst = 0;
        for (int s = 0; s <= 40; ++s) {
          const double u = -1.0 + s / 20.0;
          double v = 0;
          for (Eigen::Index j = 1; j < dc.coefficients_um.size(); ++j)
            v += dc.coefficients_um(j) * legendre(static_cast<int>(j + 1), u);
          worst = std::max(worst, std::abs(v));
        }
        dc.nonlinear_um = worst;
      }
      out.tests.push_back(dc);
    }
  }
  {
    // Direction: an offset per configuration between the readings taken backward and forward
    // (hysteresis, backlash of the sensor stage).
    Eigen::MatrixXd Z(4 * P, 0);
    if (rec.direction.size() != 0)
      for (int c = 0; c < 4; ++c) {
        const bool both =
            rec.direction.col(c).maxCoeff() > 0 && rec.direction.col(c).minCoeff() < 0;
        if (!both) continue;
        Eigen::MatrixXd Zn(4 * P, Z.cols() + 1);
        Zn.leftCols(Z.cols()) = Z;
        Zn.col(Z.cols()).setZero();
        for (int n = 0; n < P; ++n)
          Zn(4 * n + c, Z.cols()) = rec.direction(n, c) < 0 ? 1.0 : 0.0;
        Z = std::move(Zn);
      }
    DependenceTest d = polynomial_test("direction", Z);
    if (rec.direction.size() == 0)
      d.not_tested = "not recorded";
    else if (Z.cols() == 0)
      d.not_tested = "every configuration measured in one direction only";
    out.tests.push_back(d);
  }
  {
    // Reading lag: a hysteresis of the sensor reads r − h·sign(dr/dt), and with the slide at
    // ±v, dr/dt = ±v·dr/dx, so its signature is the column z = −(direction)·sign(dr/dx).  One
    // direction per configuration (a single scan) leaves most of the lag in the profile read;
    // what shows is mostly where a reading turns (the four configurations turn at different x),
    // which is where the lag itself moves the fitted readings' turn by a step of 2h: the sign of
    // dr̂/dx there is wrong, and the column at r̂ alone misses the part that shows (measured,
    // random profiles, h 0.5-1.5 um, σ 0.1: F 0.07-40 against 260-2600 with the true signs).  So
    // the signs are taken at r̂ + h·z for each h of a grid (±0.5σ̂..50σ̂, ratio 1.35; z iterated
    // four times from r̂'s signs), the F test of the column at the best h, its p times the grid's
    // size (Bonferroni: each grid point's column is a function of r̂ alone, so each test is exact;
    // the best of a search is not, Davies' problem, and the factor bounds it).
    const Eigen::MatrixXd fit = m_um - expand_residual(cfg, r);
    auto lag_column = [&](const Eigen::MatrixXd& g) {
      Eigen::MatrixXd Z(4 * P, 1);
      for (int n = 0; n < P; ++n)
        for (int i = 0; i < 4; ++i) {
          const double slope = g(std::min(n + 1, P - 1), i) - g(std::max(n - 1, 0), i);
          const double dir = rec.direction.size() != 0 && rec.direction(n, i) < 0 ? -1.0 : 1.0;
          Z(4 * n + i, 0) = -dir * (slope > 0 ? 1.0 : slope < 0 ? -1.0 : 0.0);
        }
      return Z;
    };
    const double s_hat = dof > 0 ? std::sqrt(r.squaredNorm() / dof) : 0.0;
    const Eigen::MatrixXd Z0 = lag_column(fit);
    DependenceTest d = polynomial_test("reading lag (hysteresis)", Z0);
    Eigen::MatrixXd Zbest = Z0;
    int grid = 1;
    if (d.tested && s_hat > 0) {
      for (double sign : {1.0, -1.0})
        for (double h = 0.5 * s_hat; h <= 50.0 * s_hat; h *= 1.35) {
          ++grid;
          Eigen::MatrixXd Z = Z0;
          for (int it = 0; it < 4; ++it) {
            Eigen::MatrixXd g = fit;
            for (int n = 0; n < P; ++n)
              for (int i = 0; i < 4; ++i)
                g(n, i) -= sign * h * Z(4 * n + i, 0);
            Z = lag_column(g);
          }
          DependenceTest dg = polynomial_test("reading lag (hysteresis)", Z);
          if (dg.tested && dg.statistic > d.statistic) {
            d = dg;
            Zbest = Z;
          }
        }
      d.p_value = std::min(1.0, d.p_value * grid);
      const Eigen::VectorXd zp = space.project_out(reduce_columns(cfg, Zbest)).col(0);
      d.visible_fraction = zp.norm() / Zbest.col(0).norm();
    }
    out.tests.push_back(d);
  }
  {
    DependenceTest d =
        rec.temperature_C.size() == 0
            ? polynomial_test("temperature", Eigen::MatrixXd(4 * P, 0))
            : polynomial_test("temperature",
                              legendre_columns(rec.temperature_C, opts.temperature_degree, -1, 1));
    if (rec.temperature_C.size() == 0) d.not_tested = "not recorded";
    out.tests.push_back(d);
  }

  bonferroni(out, opts.alpha);
  for (auto& d : out.tests) {
    if (!d.significant) continue;
    std::string f = "residual depends on " + d.variable + fmt(": p = %.2g", d.p_adjusted);
    if (d.variable == "configuration") {
      f +=
          fmt(" (configuration %.0f's residual %.2f times its expected share: a noisier or "
              "disturbed sensor position)",
              d.coefficients_um(0), d.statistic);
    } else if (d.variable.rfind("reading level (", 0) == 0) {
      const bool quadratic = d.variable.find("quadratic") != std::string::npos;
      f += quadratic
               ? fmt(": the sensor reads r + c·(r − %.4g um)², c = %.3g +- %.2g /um "
                     "(its slope changes %.3g %% per 100 um)",
                     0.5 * (d.range_lo_um + d.range_hi_um), d.kappa_per_um, d.u_kappa_per_um,
                     2.0 * d.kappa_per_um * 100.0 * 100.0)
               : fmt(": the sensor reads r + c·(r − %.4g um)³, c = %.3g +- %.2g /um²",
                     0.5 * (d.range_lo_um + d.range_hi_um), d.kappa3_per_um2, d.u_kappa3_per_um2);
      f += fmt("; %.3g um at the ends of readings %.4g..%.4g um; %.2g of it shows in the "
               "residual, the rest is absorbed by f, S and gamma",
               d.nonlinear_um, d.range_lo_um, d.range_hi_um, d.visible_fraction) +
           " (a sensor non-linearity: not in the effect library)";
    } else if (d.variable == "reading lag (hysteresis)") {
      f += fmt(": the sensor lags by h = %.3g um behind the change of its reading (F = %.3g; "
               "%.2g of the lag shows in the residual, the rest is absorbed by f, S and gamma)",
               d.coefficients_um.size() ? d.coefficients_um(0) : 0.0, d.statistic,
               d.visible_fraction) +
           " (a hysteresis: not in the one-scan effect library; identifiable from a plan that "
           "reads a configuration both ways: serpentine or reversed)";
    } else if (d.variable.rfind("reading level", 0) == 0) {
      f +=
          fmt(", quadratic term %.3g /um (the sensor's slope changes %.3g %% per 100 um); "
              "non-linear part up to %.3g um over readings %.4g..",
              d.kappa_per_um, 2.0 * d.kappa_per_um * 100.0 * 100.0, d.nonlinear_um, d.range_lo_um) +
          fmt("%.4g um (a non-linearity or gain of this sensor position)", d.range_hi_um);
    } else {
      f += fmt(", F = %.3g on %.0f directions", d.statistic, d.identifiable);
    }
    d.finding = f;
    out.findings.push_back(f);
  }
  out.depends = !out.findings.empty();
  return out;
}

ResidualTrace trace_sequence_residual(const SequenceTraceInput& in,
                                      const ResidualTraceOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("invalid residual trace options: " + why);
  const Eigen::Index P = in.m_um.rows(), T = in.m_um.cols();
  if (in.basis.rows() != P * T || in.t_s.rows() != P || in.t_s.cols() != T ||
      static_cast<Eigen::Index>(in.configuration.size()) != T ||
      static_cast<Eigen::Index>(in.direction.size()) != T || !in.m_um.allFinite() ||
      !in.t_s.allFinite())
    throw std::invalid_argument(
        "trace_sequence_residual: readings and times must be finite P x T, the basis PT rows, "
        "configuration and direction T entries");
  const Eigen::MatrixXd& Q = in.basis;
  Eigen::VectorXd y(P * T);
  for (Eigen::Index k = 0; k < T; ++k)
    y.segment(k * P, P) = in.m_um.col(k);
  const Eigen::VectorXd r = y - Q * (Q.transpose() * y);
  const int dof = static_cast<int>(P * T - Q.cols());
  // The nested F test of columns Z (PT × k, row k·P + n) against the fit.
  auto test = [&](const std::string& name, const Eigen::MatrixXd& Z) {
    const Nested nt = Z.cols() == 0 ? Nested{}
                                    : projected_test(Z - Q * (Q.transpose() * Z),
                                                     Z.colwise().norm().transpose(), r, dof);
    return dependence_test(name, nt, static_cast<int>(Z.cols()), dof);
  };
  // Legendre P_1..P_d of v (PT) scaled to [−1, 1] over the selected rows.
  auto legendre_of = [&](const Eigen::VectorXd& v, int degree, const std::vector<bool>& rows) {
    double lo = 0, hi = 0;
    bool any = false;
    for (Eigen::Index i = 0; i < v.size(); ++i)
      if (rows[static_cast<std::size_t>(i)]) {
        lo = any ? std::min(lo, v(i)) : v(i);
        hi = any ? std::max(hi, v(i)) : v(i);
        any = true;
      }
    if (!(hi > lo)) return Eigen::MatrixXd(v.size(), 0);
    Eigen::MatrixXd Z = Eigen::MatrixXd::Zero(v.size(), degree);
    for (Eigen::Index i = 0; i < v.size(); ++i)
      if (rows[static_cast<std::size_t>(i)])
        for (int dg = 1; dg <= degree; ++dg)
          Z(i, dg - 1) = legendre(dg, (v(i) - 0.5 * (lo + hi)) / (0.5 * (hi - lo)));
    return Z;
  };
  auto append = [](Eigen::MatrixXd& A, const Eigen::MatrixXd& B) {
    Eigen::MatrixXd C(A.rows(), A.cols() + B.cols());
    C << A, B;
    A = std::move(C);
  };
  ResidualTrace out;
  out.alpha = opts.alpha;
  const std::vector<bool> all(static_cast<std::size_t>(P * T), true);
  Eigen::VectorXd t(P * T), x(P * T);
  for (Eigen::Index k = 0; k < T; ++k)
    for (Eigen::Index n = 0; n < P; ++n) {
      t(k * P + n) = in.t_s(n, k);
      x(k * P + n) = static_cast<double>(n) * in.dx_mm;
    }
  out.tests.push_back(test("time", legendre_of(t, opts.time_degree, all)));
  {
    Eigen::MatrixXd Z(P * T, 0);
    for (int c = 0; c < 4; ++c) {
      std::vector<bool> rows(static_cast<std::size_t>(P * T), false);
      for (Eigen::Index k = 0; k < T; ++k)
        if (in.configuration[static_cast<std::size_t>(k)] == c)
          for (Eigen::Index n = 0; n < P; ++n)
            rows[static_cast<std::size_t>(k * P + n)] = true;
      append(Z, legendre_of(x, opts.position_degree, rows));
    }
    out.tests.push_back(test("position (per configuration)", Z));
  }
  // Fitted readings (independent of the residual: exact tests of columns built from them).
  const Eigen::VectorXd fit = y - r;
  {
    const double lo = fit.minCoeff(), hi = fit.maxCoeff(), mid = 0.5 * (lo + hi);
    for (int power : {2, 3}) {
      Eigen::MatrixXd Z(P * T, hi > lo ? 1 : 0);
      if (hi > lo)
        for (Eigen::Index i = 0; i < P * T; ++i)
          Z(i, 0) = std::pow(fit(i) - mid, power);
      DependenceTest d = test(power == 2 ? "reading level (quadratic non-linearity)"
                                         : "reading level (cubic non-linearity)",
                              Z);
      d.range_lo_um = lo;
      d.range_hi_um = hi;
      if (d.tested) {
        (power == 2 ? d.kappa_per_um : d.kappa3_per_um2) = d.coefficients_um(0);
        d.nonlinear_um = std::abs(d.coefficients_um(0)) * std::pow(0.5 * (hi - lo), power);
      }
      out.tests.push_back(d);
    }
  }
  {
    Eigen::MatrixXd Z(P * T, 0);
    std::vector<int> both;
    for (int c = 0; c < 4; ++c) {
      bool fwd = false, bwd = false;
      for (Eigen::Index k = 0; k < T; ++k)
        if (in.configuration[static_cast<std::size_t>(k)] == c)
          (in.direction[static_cast<std::size_t>(k)] > 0 ? fwd : bwd) = true;
      if (!(fwd && bwd)) continue;
      both.push_back(c);
      Eigen::MatrixXd Zc = Eigen::MatrixXd::Zero(P * T, 2);
      for (Eigen::Index k = 0; k < T; ++k) {
        if (in.configuration[static_cast<std::size_t>(k)] != c) continue;
        const double dir = in.direction[static_cast<std::size_t>(k)] > 0 ? 1.0 : -1.0;
        for (Eigen::Index n = 0; n < P; ++n) {
          const Eigen::Index a = k * P + std::max<Eigen::Index>(n - 1, 0),
                             b = k * P + std::min<Eigen::Index>(n + 1, P - 1);
          const double slope = fit(b) - fit(a);
          Zc(k * P + n, 0) = dir < 0 ? 1.0 : 0.0;
          Zc(k * P + n, 1) = slope > 0 ? -dir : slope < 0 ? dir : 0.0;
        }
      }
      append(Z, Zc);
    }
    DependenceTest d = test("direction", Z);
    if (both.empty())
      d.not_tested =
          "every configuration measured in one direction only: a hysteresis is not identifiable "
          "from this plan (measure each configuration forward and back)";
    out.tests.push_back(d);
  }
  bonferroni(out, opts.alpha);
  for (auto& d : out.tests) {
    if (!d.significant) continue;
    std::string f =
        "residual of every traverse depends on " + d.variable +
        fmt(": p = %.2g, F = %.3g on %.0f directions", d.p_adjusted, d.statistic, d.identifiable);
    if (d.variable == "direction") {
      // The hysteresis coefficients (every second column), their mean: h.
      double h = 0;
      int m = 0;
      for (Eigen::Index j = 1; j < d.coefficients_um.size(); j += 2, ++m)
        h += d.coefficients_um(j);
      f +=
          fmt(" (a hysteresis: the sensor lags by about %.3g um in the direction its reading "
              "changes; not in the effect library, not corrected)",
              m ? h / m : 0.0);
    } else if (d.variable.rfind("reading level (", 0) == 0) {
      f += fmt(" (a sensor non-linearity, %.3g um at the ends of readings %.4g..%.4g um)",
               d.nonlinear_um, d.range_lo_um, d.range_hi_um);
    }
    d.finding = f;
    out.findings.push_back(f);
  }
  out.depends = !out.findings.empty();
  return out;
}

}  // namespace errsep::core

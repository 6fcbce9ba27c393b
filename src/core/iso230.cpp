#include "errsep/core/iso230.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace errsep::core {
namespace {

void check_profile(const std::vector<double>& x, const std::vector<double>& s,
                   const std::vector<double>& u, const char* what) {
  if (x.size() != s.size())
    throw std::invalid_argument(std::string(what) + ": " + std::to_string(x.size()) +
                                " positions but " + std::to_string(s.size()) + " values");
  if (!u.empty() && u.size() != s.size())
    throw std::invalid_argument(std::string(what) + ": " + std::to_string(u.size()) +
                                " uncertainties for " + std::to_string(s.size()) + " values");
  if (x.size() < 2)
    throw std::invalid_argument(std::string(what) + ": need at least 2 points, got " +
                                std::to_string(x.size()));
  for (std::size_t i = 0; i < x.size(); ++i) {
    if (!std::isfinite(x[i]) || !std::isfinite(s[i]) || (!u.empty() && !std::isfinite(u[i])))
      throw std::invalid_argument(std::string(what) + ": non-finite value at point " +
                                  std::to_string(i));
    if (!u.empty() && u[i] < 0)
      throw std::invalid_argument(std::string(what) + ": negative uncertainty at point " +
                                  std::to_string(i));
    if (i > 0 && !(x[i] > x[i - 1]))
      throw std::invalid_argument(
          std::string(what) + ": positions must be strictly increasing (x[" + std::to_string(i) +
          "] = " + std::to_string(x[i]) + " after " + std::to_string(x[i - 1]) + ")");
  }
}

struct Extremes {
  std::size_t imax = 0, imin = 0;
  double max = 0, min = 0;
};

Extremes extremes(const std::vector<double>& d) {
  Extremes e;
  e.max = e.min = d[0];
  for (std::size_t i = 1; i < d.size(); ++i) {
    if (d[i] > e.max) e.max = d[i], e.imax = i;
    if (d[i] < e.min) e.min = d[i], e.imin = i;
  }
  return e;
}

double cross(double ox, double oy, double ax, double ay, double bx, double by) {
  return (ax - ox) * (by - oy) - (ay - oy) * (bx - ox);
}

// Monotone-chain hull of points sorted by x (strictly increasing): indices of the lower and the
// upper hull, each from left to right.
void hulls(const std::vector<double>& x, const std::vector<double>& s,
           std::vector<std::size_t>* lower, std::vector<std::size_t>* upper) {
  lower->clear();
  upper->clear();
  for (std::size_t i = 0; i < x.size(); ++i) {
    while (lower->size() >= 2) {
      const std::size_t a = (*lower)[lower->size() - 2], b = lower->back();
      if (cross(x[a], s[a], x[b], s[b], x[i], s[i]) <= 0)
        lower->pop_back();
      else
        break;
    }
    lower->push_back(i);
    while (upper->size() >= 2) {
      const std::size_t a = (*upper)[upper->size() - 2], b = upper->back();
      if (cross(x[a], s[a], x[b], s[b], x[i], s[i]) >= 0)
        upper->pop_back();
      else
        break;
    }
    upper->push_back(i);
  }
}

StraightnessResult straightness_unchecked(const std::vector<double>& x,
                                          const std::vector<double>& s,
                                          const std::vector<double>& u, ReferenceLine reference,
                                          const EvaluationOptions& opts) {
  const std::size_t n = x.size();
  StraightnessResult r;
  r.reference = reference;
  r.sensitivity.assign(n, 0.0);
  std::vector<double> d(n);
  switch (reference) {
    case ReferenceLine::end_points: {
      const double slope = (s[n - 1] - s[0]) / (x[n - 1] - x[0]);
      r.line = {s[0] - slope * x[0], slope};
      for (std::size_t i = 0; i < n; ++i)
        d[i] = s[i] - r.line.at(x[i]);
      const Extremes e = extremes(d);
      r.index_max = e.imax;
      r.index_min = e.imin;
      r.straightness_um = e.max - e.min;
      // d_p = s_p - (1 - t_p) s_0 - t_p s_{n-1},  t_p = (x_p - x_0) / (x_{n-1} - x_0)
      auto add_row = [&](std::size_t p, double sign) {
        const double t = (x[p] - x[0]) / (x[n - 1] - x[0]);
        r.sensitivity[p] += sign;
        r.sensitivity[0] -= sign * (1 - t);
        r.sensitivity[n - 1] -= sign * t;
      };
      add_row(e.imax, 1.0);
      add_row(e.imin, -1.0);
      break;
    }
    case ReferenceLine::least_squares: {
      double xm = 0, sm = 0;
      for (std::size_t i = 0; i < n; ++i)
        xm += x[i], sm += s[i];
      xm /= static_cast<double>(n);
      sm /= static_cast<double>(n);
      double sxx = 0, sxs = 0;
      for (std::size_t i = 0; i < n; ++i) {
        sxx += (x[i] - xm) * (x[i] - xm);
        sxs += (x[i] - xm) * (s[i] - sm);
      }
      const double slope = sxs / sxx;
      r.line = {sm - slope * xm, slope};
      for (std::size_t i = 0; i < n; ++i)
        d[i] = s[i] - r.line.at(x[i]);
      const Extremes e = extremes(d);
      r.index_max = e.imax;
      r.index_min = e.imin;
      r.straightness_um = e.max - e.min;
      // d = (I - H) s with H_pi = 1/n + (x_p - xm)(x_i - xm)/sxx
      const double dp = x[e.imax] - xm, dq = x[e.imin] - xm;
      for (std::size_t i = 0; i < n; ++i)
        r.sensitivity[i] = -(dp - dq) * (x[i] - xm) / sxx;  // the 1/n terms cancel
      r.sensitivity[e.imax] += 1.0;
      r.sensitivity[e.imin] -= 1.0;
      break;
    }
    case ReferenceLine::minimum_zone: {
      std::vector<std::size_t> lo, up;
      hulls(x, s, &lo, &up);
      double best = std::numeric_limits<double>::infinity();
      // The zone is fixed by a hull edge (a, b) on one side and the farthest point on the other.
      std::size_t ea = 0, eb = n - 1, far = 0;
      bool lower_edge = true;
      double best_slope = 0;
      auto try_edges = [&](const std::vector<std::size_t>& hull, bool is_lower) {
        for (std::size_t k = 0; k + 1 < hull.size(); ++k) {
          const std::size_t a = hull[k], b = hull[k + 1];
          const double slope = (s[b] - s[a]) / (x[b] - x[a]);
          for (std::size_t i = 0; i < n; ++i)
            d[i] = s[i] - slope * x[i];
          const Extremes e = extremes(d);
          const double w = e.max - e.min;
          if (w < best) {
            best = w;
            ea = a;
            eb = b;
            far = is_lower ? e.imax : e.imin;
            lower_edge = is_lower;
            best_slope = slope;
          }
        }
      };
      try_edges(lo, true);
      try_edges(up, false);
      for (std::size_t i = 0; i < n; ++i)
        d[i] = s[i] - best_slope * x[i];
      const Extremes e = extremes(d);
      r.line = {(e.max + e.min) / 2, best_slope};
      r.straightness_um = e.max - e.min;
      r.index_max = lower_edge ? far : ea;
      r.index_min = lower_edge ? ea : far;
      // T = +-( s_far - s_a - (s_b - s_a) t ),  t = (x_far - x_a) / (x_b - x_a)
      const double t = (x[far] - x[ea]) / (x[eb] - x[ea]);
      const double sign = lower_edge ? 1.0 : -1.0;
      r.sensitivity[far] += sign;
      r.sensitivity[ea] -= sign * (1 - t);
      r.sensitivity[eb] -= sign * t;
      break;
    }
  }
  r.uncertainty = propagate(r.sensitivity, u, opts);
  return r;
}

void require_valid(const EvaluationOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("EvaluationOptions: " + why);
}

// Least-squares plane in centred, scaled coordinates; returns the residuals and fills the
// sensitivity of (d_p - d_q).
struct ScaledXY {
  double xm = 0, ym = 0, sx = 1, sy = 1;
  std::vector<double> xs, ys;
};

ScaledXY scale_xy(const std::vector<double>& x, const std::vector<double>& y) {
  ScaledXY c;
  const std::size_t n = x.size();
  for (std::size_t i = 0; i < n; ++i)
    c.xm += x[i], c.ym += y[i];
  c.xm /= static_cast<double>(n);
  c.ym /= static_cast<double>(n);
  double mx = 0, my = 0;
  for (std::size_t i = 0; i < n; ++i) {
    mx = std::max(mx, std::abs(x[i] - c.xm));
    my = std::max(my, std::abs(y[i] - c.ym));
  }
  c.sx = mx > 0 ? mx : 1.0;
  c.sy = my > 0 ? my : 1.0;
  c.xs.resize(n);
  c.ys.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    c.xs[i] = (x[i] - c.xm) / c.sx;
    c.ys[i] = (y[i] - c.ym) / c.sy;
  }
  return c;
}

// Converts a plane a + b xs + c ys in scaled coordinates to mm.
Plane unscale(const ScaledXY& c, double a, double b, double cc) {
  Plane p;
  p.slope_x_um_per_mm = b / c.sx;
  p.slope_y_um_per_mm = cc / c.sy;
  p.offset_um = a - p.slope_x_um_per_mm * c.xm - p.slope_y_um_per_mm * c.ym;
  return p;
}

FlatnessResult flatness_least_squares(const ScaledXY& c, const std::vector<double>& w) {
  const std::size_t n = w.size();
  Eigen::Matrix3d g = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d phi(1.0, c.xs[i], c.ys[i]);
    g += phi * phi.transpose();
    rhs += phi * w[i];
  }
  const Eigen::LDLT<Eigen::Matrix3d> ldlt(g);
  const Eigen::Vector3d coef = ldlt.solve(rhs);
  FlatnessResult r;
  r.reference = ReferencePlane::least_squares;
  r.plane = unscale(c, coef[0], coef[1], coef[2]);
  std::vector<double> d(n);
  for (std::size_t i = 0; i < n; ++i)
    d[i] = w[i] - (coef[0] + coef[1] * c.xs[i] + coef[2] * c.ys[i]);
  const Extremes e = extremes(d);
  r.flatness_um = e.max - e.min;
  r.index_max = e.imax;
  r.index_min = e.imin;
  // d_p - d_q = (e_p - e_q - (phi_p - phi_q)^T G^-1 Phi^T) w
  const Eigen::Vector3d dphi(0.0, c.xs[e.imax] - c.xs[e.imin], c.ys[e.imax] - c.ys[e.imin]);
  const Eigen::Vector3d gv = ldlt.solve(dphi);
  r.sensitivity.assign(n, 0.0);
  for (std::size_t i = 0; i < n; ++i)
    r.sensitivity[i] = -(gv[0] + gv[1] * c.xs[i] + gv[2] * c.ys[i]);
  r.sensitivity[e.imax] += 1.0;
  r.sensitivity[e.imin] -= 1.0;
  return r;
}

// Minimum-zone (Chebyshev) plane.  Primal:  min e  s.t.  |w_i - (a + b x_i + c y_i)| <= e.
// Dual (4 rows, 2n + 1 columns, all >= 0):
//   max sum_i (u_i - v_i) w_i  s.t.  sum (u_i - v_i) (1, x_i, y_i) = 0,  sum (u_i + v_i) + s = 1.
// Column of u_i: (1, x_i, y_i, 1), of v_i: (-1, -x_i, -y_i, 1), slack: (0, 0, 0, 1).
// The simplex multipliers of a basis are (a, b, c, e); reduced costs are r_i - e for u_i and
// -r_i - e for v_i (r_i the residual), -e for the slack: optimal when |r_i| <= e for all i.
FlatnessResult flatness_minimum_zone(const ScaledXY& c, const std::vector<double>& w) {
  const std::size_t n = w.size();
  auto column = [&](std::size_t k) -> Eigen::Vector4d {
    if (k == 2 * n) return Eigen::Vector4d(0, 0, 0, 1);
    const std::size_t i = k < n ? k : k - n;
    const double sg = k < n ? 1.0 : -1.0;
    return Eigen::Vector4d(sg, sg * c.xs[i], sg * c.ys[i], 1.0);
  };
  auto cost = [&](std::size_t k) -> double {
    if (k == 2 * n) return 0.0;
    return k < n ? w[k] : -w[k - n];
  };

  // Initial basis: three affinely independent points and a fourth; signs from the null vector of
  // their (1, x, y) columns make the basic solution non-negative (Stiefel's initial reference).
  std::size_t p0 = 0, p1 = 0, p2 = 0;
  double best = -1;
  for (std::size_t i = 0; i < n; ++i) {
    const double dd = std::hypot(c.xs[i] - c.xs[p0], c.ys[i] - c.ys[p0]);
    if (dd > best) best = dd, p1 = i;
  }
  best = -1;
  for (std::size_t i = 0; i < n; ++i) {
    const double a = std::abs(cross(c.xs[p0], c.ys[p0], c.xs[p1], c.ys[p1], c.xs[i], c.ys[i]));
    if (a > best) best = a, p2 = i;
  }
  if (!(best > 1e-12))
    throw std::invalid_argument("flatness: all points lie on one line; a plane is not defined");
  std::size_t p3 = n;
  for (std::size_t i = 0; i < n && p3 == n; ++i)
    if (i != p0 && i != p1 && i != p2) p3 = i;
  Eigen::Matrix3d m3;
  m3 << 1, 1, 1, c.xs[p0], c.xs[p1], c.xs[p2], c.ys[p0], c.ys[p1], c.ys[p2];
  const Eigen::Vector3d m4(1, c.xs[p3], c.ys[p3]);
  const Eigen::Vector3d l3 = -m3.partialPivLu().solve(m4);
  const std::size_t pts[4] = {p0, p1, p2, p3};
  const double lam[4] = {l3[0], l3[1], l3[2], 1.0};
  std::vector<std::size_t> basis(4);
  for (int j = 0; j < 4; ++j)
    basis[j] = lam[j] >= 0 ? pts[j] : pts[j] + n;

  const Eigen::Vector4d rhs(0, 0, 0, 1);
  Eigen::Matrix4d bm;
  Eigen::Vector4d xb, pi;
  double wscale = 0;
  for (double v : w)
    wscale = std::max(wscale, std::abs(v));
  const double tol = 1e-12 * std::max(wscale, 1e-300) + 1e-300;
  const std::size_t max_iter = 100 + 50 * n;
  const std::size_t bland_after = 20 + 5 * n;
  FlatnessResult r;
  r.reference = ReferencePlane::minimum_zone;
  std::size_t it = 0;
  bool optimal = false;
  for (; it < max_iter; ++it) {
    for (int j = 0; j < 4; ++j)
      bm.col(j) = column(basis[j]);
    const Eigen::FullPivLU<Eigen::Matrix4d> lu(bm);
    xb = lu.solve(rhs);
    Eigen::Vector4d cb;
    for (int j = 0; j < 4; ++j)
      cb[j] = cost(basis[j]);
    pi = bm.transpose().fullPivLu().solve(cb);
    // Pricing: Dantzig (largest reduced cost = largest deviation), Bland when stalling.
    const bool bland = it >= bland_after;
    std::size_t enter = 2 * n + 1;
    double best_rc = tol;
    for (std::size_t k = 0; k <= 2 * n; ++k) {
      const double rc = cost(k) - pi.dot(column(k));
      if (rc > best_rc) {
        if (std::find(basis.begin(), basis.end(), k) != basis.end()) continue;
        enter = k;
        best_rc = rc;
        if (bland) break;
      }
    }
    if (enter > 2 * n) {
      optimal = true;
      break;
    }
    const Eigen::Vector4d dir = lu.solve(column(enter));
    std::size_t leave = 4;
    double theta = std::numeric_limits<double>::infinity();
    for (int j = 0; j < 4; ++j) {
      if (dir[j] > 1e-12) {
        const double ratio = std::max(xb[j], 0.0) / dir[j];
        if (ratio < theta - 1e-15 ||
            (ratio <= theta + 1e-15 && leave < 4 && basis[j] < basis[leave])) {
          theta = ratio;
          leave = static_cast<std::size_t>(j);
        }
      }
    }
    if (leave == 4) break;  // cannot happen for this bounded dual; treated as not converged
    basis[leave] = enter;
  }
  r.iterations = it;
  r.converged = optimal;
  // pi = (a, b, c, e) in scaled coordinates.
  r.plane = unscale(c, pi[0], pi[1], pi[2]);
  std::vector<double> d(n);
  for (std::size_t i = 0; i < n; ++i)
    d[i] = w[i] - (pi[0] + pi[1] * c.xs[i] + pi[2] * c.ys[i]);
  const Extremes e = extremes(d);
  r.flatness_um = e.max - e.min;
  r.plane.offset_um += (e.max + e.min) / 2;  // mid-plane of the zone
  r.index_max = e.imax;
  r.index_min = e.imin;
  // T = 2 e = 2 sum_basis cost_k xb_k: dT/dw_i = 2 (u_i - v_i).
  r.sensitivity.assign(n, 0.0);
  for (int j = 0; j < 4; ++j) {
    const std::size_t k = basis[j];
    if (k == 2 * n) continue;
    if (k < n)
      r.sensitivity[k] += 2 * xb[j];
    else
      r.sensitivity[k - n] -= 2 * xb[j];
  }
  return r;
}

int axis_index(char a, const char* what) {
  switch (std::toupper(static_cast<unsigned char>(a))) {
    case 'X':
      return 0;
    case 'Y':
      return 1;
    case 'Z':
      return 2;
    default:
      throw std::invalid_argument(std::string(what) + ": axis '" + std::string(1, a) +
                                  "' is not X, Y or Z");
  }
}

}  // namespace

const char* to_string(ReferenceLine r) {
  switch (r) {
    case ReferenceLine::end_points:
      return "end_points";
    case ReferenceLine::least_squares:
      return "least_squares";
    case ReferenceLine::minimum_zone:
      return "minimum_zone";
  }
  return "?";
}

std::optional<ReferenceLine> parse_reference_line(std::string_view s) {
  for (const auto r :
       {ReferenceLine::end_points, ReferenceLine::least_squares, ReferenceLine::minimum_zone})
    if (s == to_string(r)) return r;
  return std::nullopt;
}

const char* label(ReferenceLine r) {
  switch (r) {
    case ReferenceLine::end_points:
      return "end-point line";
    case ReferenceLine::least_squares:
      return "least-squares line";
    case ReferenceLine::minimum_zone:
      return "minimum zone";
  }
  return "?";
}

const char* to_string(ReferencePlane r) {
  return r == ReferencePlane::least_squares ? "least_squares" : "minimum_zone";
}

const char* label(ReferencePlane r) {
  return r == ReferencePlane::least_squares ? "least-squares plane" : "minimum zone";
}

const char* to_string(Correlation c) {
  return c == Correlation::uncorrelated ? "uncorrelated" : "bound";
}

bool EvaluationOptions::is_valid(std::string* why) const {
  if (!(coverage_factor > 0) || !std::isfinite(coverage_factor)) {
    if (why) *why = "coverage_factor = " + std::to_string(coverage_factor) + " must be > 0";
    return false;
  }
  return true;
}

FigureUncertainty propagate(const std::vector<double>& c, const std::vector<double>& u,
                            const EvaluationOptions& opts) {
  FigureUncertainty fu;
  fu.coverage_factor = opts.coverage_factor;
  if (u.empty()) return fu;
  double sq = 0, ab = 0;
  for (std::size_t i = 0; i < c.size(); ++i) {
    sq += c[i] * c[i] * u[i] * u[i];
    ab += std::abs(c[i]) * u[i];
  }
  fu.u_uncorrelated = std::sqrt(sq);
  fu.u_bound = ab;
  fu.expanded = opts.coverage_factor *
                (opts.correlation == Correlation::uncorrelated ? fu.u_uncorrelated : fu.u_bound);
  return fu;
}

double propagate_covariance(const std::vector<double>& c, const Eigen::MatrixXd& cov) {
  const auto n = static_cast<Eigen::Index>(c.size());
  if (cov.rows() != n || cov.cols() != n)
    throw std::invalid_argument("propagate_covariance: covariance is " +
                                std::to_string(cov.rows()) + "x" + std::to_string(cov.cols()) +
                                ", sensitivity has " + std::to_string(c.size()) + " entries");
  const Eigen::Map<const Eigen::VectorXd> cv(c.data(), n);
  const double v = cv.dot(cov * cv);
  return std::sqrt(std::max(v, 0.0));
}

StraightnessResult evaluate_straightness(const std::vector<double>& x_mm,
                                         const std::vector<double>& s_um,
                                         const std::vector<double>& u_um, ReferenceLine reference,
                                         const EvaluationOptions& opts) {
  require_valid(opts);
  check_profile(x_mm, s_um, u_um, "straightness");
  return straightness_unchecked(x_mm, s_um, u_um, reference, opts);
}

StraightnessEstimate estimate_straightness(const std::vector<double>& x_mm,
                                           const std::vector<double>& s_um,
                                           const ProfileVariance& variance,
                                           const ProfileSampler& sampler, ReferenceLine reference,
                                           int draws, std::uint64_t seed,
                                           const EvaluationOptions& opts) {
  require_valid(opts);
  check_profile(x_mm, s_um, {}, "straightness");
  if (draws < 20)
    throw std::invalid_argument("straightness: " + std::to_string(draws) +
                                " Monte Carlo draws, need at least 20");
  StraightnessEstimate out;
  out.draws = draws;
  out.zone = straightness_unchecked(x_mm, s_um, {}, reference, opts);
  const std::size_t n = s_um.size();
  std::vector<double> dev, sd(n);
  double sum = 0.0, sum2 = 0.0;
  for (int k = 0; k < draws; ++k) {
    sampler(seed + static_cast<std::uint64_t>(k), dev);
    if (dev.size() != n)
      throw std::invalid_argument("straightness: a draw has " + std::to_string(dev.size()) +
                                  " points, the profile " + std::to_string(n));
    for (std::size_t i = 0; i < n; ++i)
      sd[i] = s_um[i] + dev[i];
    const StraightnessResult z = straightness_unchecked(x_mm, sd, {}, reference, opts);
    sum += z.straightness_um;
    sum2 += z.straightness_um * z.straightness_um;
  }
  const double mean = sum / draws;
  const double var_draws = std::max(0.0, sum2 / draws - mean * mean);
  out.bias_um = mean - out.zone.straightness_um;
  // u: cᵀVc is the spread of the figure while the points that fix the zone stay the same; where
  // the noise chooses them (a long scan whose S is barely determined, or near-equal extremes),
  // the figure moves more than that, and the spread of the draws' figures measures it (issue 15:
  // N = 5000, σ = 0.1 µm, u from cᵀVc 4.9 µm where the draws spread 12.5 µm and the error was
  // 19 µm).  Where the profile fixes the zone the two agree; the larger is taken.  The Monte
  // Carlo error of the removed bias, var/draws, is added.
  const double u_lin2 = std::max(0.0, variance(out.zone.sensitivity));
  // A straightness is max − min about a line, never negative: where the removed bias exceeds the
  // figure (noise-dominated), the corrected figure is clipped at 0, which for any true figure
  // (>= 0) brings it closer.
  out.straightness_um = std::max(0.0, out.zone.straightness_um - out.bias_um);
  out.u_um = std::sqrt(std::max(u_lin2, var_draws) + var_draws / draws);
  out.expanded_um = opts.coverage_factor * out.u_um;
  out.zone.uncertainty.expanded = out.expanded_um;
  out.zone.uncertainty.coverage_factor = opts.coverage_factor;
  return out;
}

LocalStraightnessResult evaluate_local_straightness(const std::vector<double>& x_mm,
                                                    const std::vector<double>& s_um,
                                                    const std::vector<double>& u_um,
                                                    double local_length_mm, ReferenceLine reference,
                                                    const EvaluationOptions& opts) {
  require_valid(opts);
  check_profile(x_mm, s_um, u_um, "local straightness");
  const std::size_t n = x_mm.size();
  const double span = x_mm[n - 1] - x_mm[0];
  // A relative tolerance so that a window of exactly k sample steps is not lost to rounding.
  const double eps = 1e-9 * std::max(span, 1.0);
  if (!(local_length_mm > 0) || local_length_mm > span + eps)
    throw std::invalid_argument("local straightness: local length " +
                                std::to_string(local_length_mm) + " mm must be > 0 and at most " +
                                "the measured length " + std::to_string(span) + " mm");
  LocalStraightnessResult out;
  out.local_length_mm = local_length_mm;
  out.reference = reference;
  out.straightness_um = -1;
  std::vector<double> wx, ws, wu;
  std::size_t end = 0;
  for (std::size_t start = 0; start < n; ++start) {
    const double x_end = x_mm[start] + local_length_mm;
    if (x_end > x_mm[n - 1] + eps) break;
    end = std::max(end, start);
    while (end + 1 < n && x_mm[end + 1] <= x_end + eps)
      ++end;
    if (end - start + 1 < 2) continue;
    wx.assign(x_mm.begin() + static_cast<std::ptrdiff_t>(start),
              x_mm.begin() + static_cast<std::ptrdiff_t>(end + 1));
    ws.assign(s_um.begin() + static_cast<std::ptrdiff_t>(start),
              s_um.begin() + static_cast<std::ptrdiff_t>(end + 1));
    if (u_um.empty())
      wu.clear();
    else
      wu.assign(u_um.begin() + static_cast<std::ptrdiff_t>(start),
                u_um.begin() + static_cast<std::ptrdiff_t>(end + 1));
    const StraightnessResult r = straightness_unchecked(wx, ws, wu, reference, opts);
    ++out.windows;
    if (r.straightness_um > out.straightness_um) {
      out.straightness_um = r.straightness_um;
      out.uncertainty = r.uncertainty;
      out.window_start_mm = x_mm[start];
      out.window_end_mm = x_mm[end];
    }
  }
  if (out.windows == 0)
    throw std::invalid_argument("local straightness: no window of " +
                                std::to_string(local_length_mm) + " mm holds 2 samples");
  return out;
}

AngularResult evaluate_angular_deviation(const std::vector<double>& gamma_urad,
                                         const std::vector<double>& u_urad,
                                         const EvaluationOptions& opts) {
  require_valid(opts);
  if (gamma_urad.empty()) throw std::invalid_argument("angular deviation: no values");
  if (!u_urad.empty() && u_urad.size() != gamma_urad.size())
    throw std::invalid_argument("angular deviation: " + std::to_string(u_urad.size()) +
                                " uncertainties for " + std::to_string(gamma_urad.size()) +
                                " values");
  for (double g : gamma_urad)
    if (!std::isfinite(g)) throw std::invalid_argument("angular deviation: non-finite value");
  const Extremes e = extremes(gamma_urad);
  AngularResult r;
  r.max_urad = e.max;
  r.min_urad = e.min;
  r.index_max = e.imax;
  r.index_min = e.imin;
  r.deviation_urad = e.max - e.min;
  r.deviation_arcsec = r.deviation_urad * kArcsecPerUrad;
  std::vector<double> c(gamma_urad.size(), 0.0);
  if (e.imax != e.imin) {
    c[e.imax] = 1.0;
    c[e.imin] = -1.0;
  }
  r.uncertainty = propagate(c, u_urad, opts);
  r.expanded_uncertainty_arcsec = r.uncertainty.expanded * kArcsecPerUrad;
  return r;
}

FlatnessResult evaluate_flatness(const std::vector<double>& x_mm, const std::vector<double>& y_mm,
                                 const std::vector<double>& w_um, const std::vector<double>& u_um,
                                 ReferencePlane reference, const EvaluationOptions& opts) {
  require_valid(opts);
  const std::size_t n = w_um.size();
  if (x_mm.size() != n || y_mm.size() != n)
    throw std::invalid_argument("flatness: x, y and w must have the same length (" +
                                std::to_string(x_mm.size()) + ", " + std::to_string(y_mm.size()) +
                                ", " + std::to_string(n) + ")");
  if (!u_um.empty() && u_um.size() != n)
    throw std::invalid_argument("flatness: " + std::to_string(u_um.size()) + " uncertainties for " +
                                std::to_string(n) + " values");
  if (n < 3) throw std::invalid_argument("flatness: need at least 3 points");
  for (std::size_t i = 0; i < n; ++i)
    if (!std::isfinite(x_mm[i]) || !std::isfinite(y_mm[i]) || !std::isfinite(w_um[i]))
      throw std::invalid_argument("flatness: non-finite value at point " + std::to_string(i));
  const ScaledXY c = scale_xy(x_mm, y_mm);
  // Reject collinear point sets for both methods (the least-squares plane is not unique either).
  {
    double best = 0;
    std::size_t p1 = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const double dd = std::hypot(c.xs[i] - c.xs[0], c.ys[i] - c.ys[0]);
      if (dd > best) best = dd, p1 = i;
    }
    double area = 0;
    for (std::size_t i = 0; i < n; ++i)
      area =
          std::max(area, std::abs(cross(c.xs[0], c.ys[0], c.xs[p1], c.ys[p1], c.xs[i], c.ys[i])));
    if (!(area > 1e-12))
      throw std::invalid_argument("flatness: all points lie on one line; a plane is not defined");
  }
  // Three points: the plane through them is both the least-squares and the minimum-zone plane.
  FlatnessResult r = reference == ReferencePlane::least_squares || n == 3
                         ? flatness_least_squares(c, w_um)
                         : flatness_minimum_zone(c, w_um);
  r.reference = reference;
  r.uncertainty = propagate(r.sensitivity, u_um, opts);
  return r;
}

std::string straightness_symbol(char moving_axis, char direction) {
  const int m = axis_index(moving_axis, "straightness symbol");
  const int d = axis_index(direction, "straightness symbol");
  if (m == d)
    throw std::invalid_argument("straightness symbol: direction must differ from the moving axis");
  const char names[] = {'X', 'Y', 'Z'};
  return std::string("E") + names[d] + names[m];
}

std::string angular_symbol(char moving_axis, char direction) {
  const int m = axis_index(moving_axis, "angular symbol");
  const int d = axis_index(direction, "angular symbol");
  if (m == d)
    throw std::invalid_argument("angular symbol: direction must differ from the moving axis");
  const char rot[] = {'A', 'B', 'C'};  // rotation about X, Y, Z
  const char names[] = {'X', 'Y', 'Z'};
  return std::string("E") + rot[3 - m - d] + names[m];
}

std::string positioning_symbol(char axis) {
  const int m = axis_index(axis, "positioning symbol");
  const char names[] = {'X', 'Y', 'Z'};
  return std::string("E") + names[m] + names[m];
}

}  // namespace errsep::core

#include "errsep/core/compensation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace errsep::core {
namespace {

void require(const CompensationOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("CompensationOptions: " + why);
}

// Largest |polyline through (x[b_k], y[b_k]) - y_i| over all samples.
void polyline_error(const std::vector<double>& x, const std::vector<double>& y,
                    const std::vector<std::size_t>& bp, double* max_err, double* rms_err) {
  double mx = 0, sq = 0;
  for (std::size_t k = 0; k + 1 < bp.size(); ++k) {
    const std::size_t a = bp[k], b = bp[k + 1];
    const double slope = (y[b] - y[a]) / (x[b] - x[a]);
    for (std::size_t i = a; i < b; ++i) {
      const double e = std::abs(y[a] + slope * (x[i] - x[a]) - y[i]);
      mx = std::max(mx, e);
      sq += e * e;
    }
  }
  *max_err = mx;
  *rms_err = std::sqrt(sq / static_cast<double>(x.size()));
}

// Fewest breakpoints (among candidate sample indices `cand`, which include 0 and n-1) such that
// every sample lies within eps of the polyline.  Returns the breakpoints, or empty if more than
// max_points are needed.
std::vector<std::size_t> fewest_breakpoints(const std::vector<double>& x,
                                            const std::vector<double>& y,
                                            const std::vector<std::size_t>& cand, double eps,
                                            std::size_t max_points) {
  const std::size_t c = cand.size();
  const std::size_t inf = std::numeric_limits<std::size_t>::max();
  std::vector<std::size_t> dist(c, inf), prev(c, inf);
  dist[0] = 1;
  // cand_pos[i] = index in cand of sample i, or inf.
  std::vector<std::size_t> cand_pos(x.size(), inf);
  for (std::size_t k = 0; k < c; ++k)
    cand_pos[cand[k]] = k;
  for (std::size_t ci = 0; ci + 1 < c; ++ci) {
    if (dist[ci] == inf || dist[ci] >= max_points) continue;
    const std::size_t i = cand[ci];
    double lo = -std::numeric_limits<double>::infinity();
    double hi = std::numeric_limits<double>::infinity();
    for (std::size_t k = i + 1; k < x.size(); ++k) {
      const double dx = x[k] - x[i];
      const double slope = (y[k] - y[i]) / dx;
      // Segment (i, k) is admissible if its slope lies in the cone of the samples between.
      if (cand_pos[k] != inf && slope >= lo - 1e-15 * std::abs(lo) &&
          slope <= hi + 1e-15 * std::abs(hi)) {
        const std::size_t ck = cand_pos[k];
        if (dist[ci] + 1 < dist[ck]) {
          dist[ck] = dist[ci] + 1;
          prev[ck] = ci;
        }
      }
      lo = std::max(lo, (y[k] - eps - y[i]) / dx);
      hi = std::min(hi, (y[k] + eps - y[i]) / dx);
      if (lo > hi) break;  // constraints only accumulate: no later k can be admissible
    }
  }
  if (dist[c - 1] == inf || dist[c - 1] > max_points) return {};
  std::vector<std::size_t> path;
  for (std::size_t k = c - 1; k != inf; k = prev[k])
    path.push_back(cand[k]);
  std::reverse(path.begin(), path.end());
  return path;
}

}  // namespace

bool CompensationOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(step_mm > 0) || !std::isfinite(step_mm))
    return fail("step_mm = " + std::to_string(step_mm) + " must be > 0");
  if (error_sign != 1.0 && error_sign != -1.0)
    return fail("error_sign = " + std::to_string(error_sign) + " must be +1 or -1");
  if (max_points == 1)
    return fail("max_points = 1: a table needs at least 2 points (0 = no limit)");
  return true;
}

bool BreakpointOptions::is_valid(std::string* why) const {
  if (max_points < 2) {
    if (why) *why = "max_points = " + std::to_string(max_points) + " must be >= 2";
    return false;
  }
  if (max_candidates < max_points) {
    if (why) *why = "max_candidates = " + std::to_string(max_candidates) + " must be >= max_points";
    return false;
  }
  return true;
}

double interpolate_hold(const std::vector<double>& xs, const std::vector<double>& ys, double x) {
  if (xs.empty()) return 0;
  if (x <= xs.front()) return ys.front();
  if (x >= xs.back()) return ys.back();
  const auto it = std::upper_bound(xs.begin(), xs.end(), x);
  const std::size_t j = static_cast<std::size_t>(it - xs.begin());
  const std::size_t i = j - 1;
  const double f = (x - xs[i]) / (xs[j] - xs[i]);
  return ys[i] + f * (ys[j] - ys[i]);
}

std::vector<double> error_to_compensate(const std::vector<double>& x_mm,
                                        const std::vector<double>& s_um,
                                        const CompensationOptions& opts) {
  require(opts);
  // evaluate_straightness validates the profile (sizes, finite, strictly increasing x).
  std::vector<double> e(s_um.size());
  for (std::size_t i = 0; i < e.size() && i < s_um.size(); ++i)
    e[i] = opts.error_sign * s_um[i];
  const ReferenceLine ref = opts.remove_line.value_or(ReferenceLine::end_points);
  const StraightnessResult r = evaluate_straightness(x_mm, e, {}, ref);
  if (opts.remove_line)
    for (std::size_t i = 0; i < e.size(); ++i)
      e[i] -= r.line.at(x_mm[i]);
  return e;
}

UniformCompensationTable make_uniform_table(const std::vector<double>& x_mm,
                                            const std::vector<double>& s_um,
                                            const CompensationOptions& opts) {
  const std::vector<double> e = error_to_compensate(x_mm, s_um, opts);
  std::vector<double> c(e.size());
  for (std::size_t i = 0; i < e.size(); ++i)
    c[i] = -e[i];
  const double span = x_mm.back() - x_mm.front();
  const auto steps =
      static_cast<std::size_t>(std::ceil(span / opts.step_mm - 1e-9 * std::max(1.0, span)));
  const std::size_t n = std::max<std::size_t>(steps, 1) + 1;
  if (opts.max_points != 0 && n > opts.max_points)
    throw std::invalid_argument(
        "compensation table: " + std::to_string(n) + " points at step " +
        std::to_string(opts.step_mm) + " mm over " + std::to_string(span) +
        " mm exceed the limit of " + std::to_string(opts.max_points) + " (use a step of at least " +
        std::to_string(span / static_cast<double>(opts.max_points - 1)) + " mm)");
  UniformCompensationTable t;
  t.start_mm = x_mm.front();
  t.step_mm = opts.step_mm;
  t.comp_um.resize(n);
  std::vector<double> xs(n);
  for (std::size_t i = 0; i < n; ++i) {
    xs[i] = t.start_mm + opts.step_mm * static_cast<double>(i);
    t.comp_um[i] = interpolate_hold(x_mm, c, xs[i]);
  }
  double mx = 0;
  for (std::size_t i = 0; i < x_mm.size(); ++i)
    mx = std::max(mx, std::abs(interpolate_hold(xs, t.comp_um, x_mm[i]) - c[i]));
  t.max_interpolation_error_um = mx;
  return t;
}

BreakpointTable make_breakpoint_table(const std::vector<double>& x_mm,
                                      const std::vector<double>& s_um,
                                      const CompensationOptions& opts,
                                      const BreakpointOptions& bopts) {
  std::string why;
  if (!bopts.is_valid(&why)) throw std::invalid_argument("BreakpointOptions: " + why);
  const std::vector<double> e = error_to_compensate(x_mm, s_um, opts);
  const std::size_t n = e.size();
  std::vector<double> c(n);
  for (std::size_t i = 0; i < n; ++i)
    c[i] = -e[i];
  BreakpointTable t;
  std::vector<std::size_t> cand;
  if (n <= bopts.max_candidates) {
    for (std::size_t i = 0; i < n; ++i)
      cand.push_back(i);
  } else {
    for (std::size_t k = 0; k < bopts.max_candidates; ++k)
      cand.push_back(static_cast<std::size_t>(
          std::llround(static_cast<double>(k) * static_cast<double>(n - 1) /
                       static_cast<double>(bopts.max_candidates - 1))));
    cand.erase(std::unique(cand.begin(), cand.end()), cand.end());
  }
  t.candidates = cand.size();
  std::vector<std::size_t> best;
  if (n <= bopts.max_points) {
    for (std::size_t i = 0; i < n; ++i)
      best.push_back(i);
  } else {
    // Upper bound: the chord through the two ends.
    std::vector<std::size_t> chord = {0, n - 1};
    double hi = 0, rms = 0;
    polyline_error(x_mm, c, chord, &hi, &rms);
    best = chord;
    double lo = 0;
    // Bisection on eps; the feasible set is monotone in eps.
    for (int it = 0; it < 100 && hi - lo > 1e-12 * std::max(hi, 1e-300); ++it) {
      const double mid = (lo + hi) / 2;
      auto path = fewest_breakpoints(x_mm, c, cand, mid, bopts.max_points);
      if (path.empty()) {
        lo = mid;
      } else {
        hi = mid;
        best = std::move(path);
      }
    }
  }
  for (std::size_t k : best) {
    t.x_mm.push_back(x_mm[k]);
    t.comp_um.push_back(c[k]);
  }
  polyline_error(x_mm, c, best, &t.max_interpolation_error_um, &t.rms_interpolation_error_um);
  return t;
}

}  // namespace errsep::core

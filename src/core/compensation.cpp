#include "errsep/core/compensation.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

namespace errsep::core {
namespace {

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

std::string fmt(double v) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

// Nodes at first + i * span / m, i = 0..m (the last exactly at `last`), values from the profile.
CompensationTable uniform_nodes(const CompensationProfile& p, std::size_t m) {
  CompensationTable t;
  const double first = p.first_mm(), last = p.last_mm();
  t.step_mm = (last - first) / static_cast<double>(m);
  for (std::size_t i = 0; i <= m; ++i) {
    const double x = i == m ? last : first + t.step_mm * static_cast<double>(i);
    t.position_mm.push_back(x);
    t.comp_um.push_back(p.at(x));
  }
  return t;
}

bool uniformly_spaced(const std::vector<double>& x) {
  const double span = x.back() - x.front();
  const double h = span / static_cast<double>(x.size() - 1);
  for (std::size_t i = 0; i < x.size(); ++i)
    if (std::abs(x[i] - (x.front() + h * static_cast<double>(i))) > 1e-9 * std::max(1.0, span))
      return false;
  return true;
}

}  // namespace

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

double CompensationProfile::at(double p_mm) const {
  return interpolate_hold(position_mm, comp_um, p_mm);
}

double CompensationTable::at(double p_mm) const {
  return interpolate_hold(position_mm, comp_um, p_mm);
}

CompensationProfile compensation_profile(const std::vector<double>& x_mm,
                                         const std::vector<double>& s_um,
                                         const std::vector<double>& u_s_um, const MachineAxes& axes,
                                         const CompensationOptions& opts) {
  std::string why;
  if (!axes.is_valid(&why)) throw std::invalid_argument("machine axes: " + why);
  if (!u_s_um.empty() && u_s_um.size() != s_um.size())
    throw std::invalid_argument("compensation profile: " + std::to_string(u_s_um.size()) +
                                " uncertainties for " + std::to_string(s_um.size()) + " values");
  // e(p(x)) = reading_sign * S(x); evaluate_straightness validates sizes, finiteness and order.
  std::vector<double> e(s_um.size());
  for (std::size_t i = 0; i < e.size(); ++i)
    e[i] = axes.reading_sign * s_um[i];
  const StraightnessResult r =
      evaluate_straightness(x_mm, e, {}, opts.remove_line.value_or(ReferenceLine::end_points));
  CompensationProfile p;
  p.axes = axes;
  p.removed_line = opts.remove_line;
  const std::size_t n = e.size();
  p.position_mm.resize(n);
  p.comp_um.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    // A scan towards - lists decreasing machine positions: store them increasing.
    const std::size_t k = axes.scan_direction > 0 ? i : n - 1 - i;
    p.position_mm[k] = axes.machine_mm(x_mm[i]);
    p.comp_um[k] = -(e[i] - (opts.remove_line ? r.line.at(x_mm[i]) : 0.0));
  }
  if (!u_s_um.empty()) {
    p.u_um = u_s_um;
    if (axes.scan_direction < 0) std::reverse(p.u_um.begin(), p.u_um.end());
  }
  return p;
}

TableAccuracy table_accuracy(const CompensationProfile& profile, const CompensationTable& table,
                             double extra_um) {
  TableAccuracy a;
  if (table.position_mm.empty()) throw std::invalid_argument("table_accuracy: empty table");
  double sq = 0;
  auto see = [&](double p, bool sample) {
    const double d = std::abs(table.at(p) - profile.at(p));
    if (d > a.max_um) {
      a.max_um = d;
      a.position_of_max_mm = p;
    }
    if (sample) sq += d * d;
  };
  for (double p : profile.position_mm)
    see(p, true);
  for (double p : table.position_mm)
    if (p >= profile.first_mm() && p <= profile.last_mm()) see(p, false);
  a.rms_um = std::sqrt(sq / static_cast<double>(profile.position_mm.size()));
  a.max_um += extra_um;
  return a;
}

bool UniformTableOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (step_mm < 0 || !std::isfinite(step_mm))
    return fail("step_mm = " + fmt(step_mm) + " must be > 0 (or 0: chosen from the data)");
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

CompensationTable make_uniform_table(const CompensationProfile& profile,
                                     const UniformTableOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("UniformTableOptions: " + why);
  const std::size_t n = profile.position_mm.size();
  if (n < 2) throw std::invalid_argument("compensation table: fewer than 2 measured positions");
  const double span = profile.last_mm() - profile.first_mm();
  const std::size_t limit = opts.max_points;
  if (opts.step_mm > 0) {
    const double m = span / opts.step_mm;
    const double mr = std::round(m);
    if (mr < 1 || std::abs(m - mr) > 1e-6 * std::max(1.0, m))
      throw std::invalid_argument(
          "compensation table: step " + fmt(opts.step_mm) + " mm does not divide the measured " +
          "range " + fmt(profile.first_mm()) + " .. " + fmt(profile.last_mm()) + " mm (" +
          fmt(span) + " mm); nodes outside the measured range would not represent it: use " +
          fmt(span / std::max(1.0, std::floor(m))) + " or " + fmt(span / std::ceil(m)) +
          " mm, or 0 to choose from the data");
    const auto m_int = static_cast<std::size_t>(mr);
    if (limit != 0 && m_int + 1 > limit)
      throw std::invalid_argument(
          "compensation table: " + std::to_string(m_int + 1) + " points at step " +
          fmt(opts.step_mm) + " mm exceed the " + "controller's limit of " + std::to_string(limit) +
          " (use a step of at least " + fmt(span / static_cast<double>(limit - 1)) + " mm)");
    return uniform_nodes(profile, m_int);
  }
  // Chosen from the data: the samples themselves when they are uniform and fit the limit.
  const bool uniform = uniformly_spaced(profile.position_mm);
  if (uniform && (limit == 0 || n <= limit)) return uniform_nodes(profile, n - 1);
  // Otherwise every whole-sample spacing that fits (nodes on samples) and the finest spacing the
  // limit allows; the one that represents the measurement best wins (fewer points on a tie).
  std::vector<std::size_t> candidates;
  const std::size_t max_intervals = limit == 0 ? n - 1 : limit - 1;
  if (uniform)
    for (std::size_t k = 1; k <= n - 1; ++k)
      if ((n - 1) % k == 0 && (n - 1) / k <= max_intervals) candidates.push_back((n - 1) / k);
  candidates.push_back(std::min(max_intervals, n - 1));
  CompensationTable best;
  double best_err = std::numeric_limits<double>::infinity();
  for (std::size_t m : candidates) {
    CompensationTable t = uniform_nodes(profile, m);
    const double err = table_accuracy(profile, t).max_um;
    if (err < best_err - 1e-12 || (std::abs(err - best_err) <= 1e-12 && m < best.points() - 1)) {
      best_err = err;
      best = std::move(t);
    }
  }
  return best;
}

CompensationTable make_breakpoint_table(const CompensationProfile& profile,
                                        const BreakpointOptions& bopts) {
  std::string why;
  if (!bopts.is_valid(&why)) throw std::invalid_argument("BreakpointOptions: " + why);
  const std::vector<double>& x = profile.position_mm;
  const std::vector<double>& c = profile.comp_um;
  const std::size_t n = c.size();
  if (n < 2) throw std::invalid_argument("compensation table: fewer than 2 measured positions");
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
  std::vector<std::size_t> best;
  if (n <= bopts.max_points) {
    for (std::size_t i = 0; i < n; ++i)
      best.push_back(i);
  } else {
    // Upper bound: the chord through the two ends.
    std::vector<std::size_t> chord = {0, n - 1};
    double hi = 0, rms = 0;
    polyline_error(x, c, chord, &hi, &rms);
    best = chord;
    double lo = 0;
    // Bisection on eps; the feasible set is monotone in eps.
    for (int it = 0; it < 100 && hi - lo > 1e-12 * std::max(hi, 1e-300); ++it) {
      const double mid = (lo + hi) / 2;
      auto path = fewest_breakpoints(x, c, cand, mid, bopts.max_points);
      if (path.empty()) {
        lo = mid;
      } else {
        hi = mid;
        best = std::move(path);
      }
    }
  }
  CompensationTable t;
  for (std::size_t k : best) {
    t.position_mm.push_back(x[k]);
    t.comp_um.push_back(c[k]);
  }
  return t;
}

}  // namespace errsep::core

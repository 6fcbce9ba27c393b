#include "errsep/core/compensation_verification.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "errsep/core/compensation.hpp"

namespace errsep::core {

MachineError machine_error(const std::vector<double>& x_mm, const std::vector<double>& s_um,
                           const std::vector<double>& u_s_um, const MachineAxes& axes) {
  std::string why;
  if (!axes.is_valid(&why)) throw std::invalid_argument("machine axes: " + why);
  if (x_mm.size() != s_um.size() || (!u_s_um.empty() && u_s_um.size() != s_um.size()))
    throw std::invalid_argument("machine_error: x, S and u_S differ in length");
  const std::size_t n = s_um.size();
  MachineError m;
  m.position_mm.resize(n);
  m.e_um.resize(n);
  if (!u_s_um.empty()) m.u_um.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t k = axes.scan_direction > 0 ? i : n - 1 - i;
    m.position_mm[k] = axes.machine_mm(x_mm[i]);
    m.e_um[k] = axes.reading_sign * s_um[i];
    if (!u_s_um.empty()) m.u_um[k] = u_s_um[i];
  }
  return m;
}

VerificationResult verify_compensation(const MachineError& before, const MachineError& after,
                                       const std::function<double(double)>& comp_um,
                                       const EvaluationOptions& opts) {
  if (before.position_mm.empty() || after.position_mm.empty())
    throw std::invalid_argument("verify_compensation: an empty scan");
  VerificationResult r;
  const double lo = after.position_mm.front(), hi = after.position_mm.back();
  const double tol = 1e-9 * std::max(1.0, std::abs(hi) + std::abs(lo));
  for (std::size_t i = 0; i < before.position_mm.size(); ++i) {
    const double p = before.position_mm[i];
    if (p < lo - tol || p > hi + tol) continue;
    r.position_mm.push_back(p);
    r.e_before_um.push_back(before.e_um[i]);
    r.u_before_um.push_back(before.u_um.empty() ? 0.0 : before.u_um[i]);
    r.e_predicted_um.push_back(before.e_um[i] + comp_um(p));
    r.e_measured_um.push_back(interpolate_hold(after.position_mm, after.e_um, p));
    r.u_measured_um.push_back(
        after.u_um.empty() ? 0.0 : interpolate_hold(after.position_mm, after.u_um, p));
  }
  r.points = r.position_mm.size();
  if (r.points < 3)
    throw std::invalid_argument(
        "verify_compensation: the two scans share " + std::to_string(r.points) +
        " positions (first " + std::to_string(before.position_mm.front()) + " .. " +
        std::to_string(before.position_mm.back()) + " mm, second " + std::to_string(lo) + " .. " +
        std::to_string(hi) + " mm); they must cover the same range");
  const auto mz = ReferenceLine::minimum_zone;
  r.before = evaluate_straightness(r.position_mm, r.e_before_um, r.u_before_um, mz, opts);
  r.predicted = evaluate_straightness(r.position_mm, r.e_predicted_um, r.u_before_um, mz, opts);
  r.measured = evaluate_straightness(r.position_mm, r.e_measured_um, r.u_measured_um, mz, opts);
  r.difference_um = r.measured.straightness_um - r.predicted.straightness_um;
  r.allowed_um = r.measured.uncertainty.expanded + r.predicted.uncertainty.expanded;
  r.consistent = std::abs(r.difference_um) <= r.allowed_um;
  r.ratio =
      r.before.straightness_um > 0 ? r.measured.straightness_um / r.before.straightness_um : 0.0;
  // Point by point, less the least-squares line of the difference.
  std::vector<double> d(r.points);
  for (std::size_t i = 0; i < r.points; ++i)
    d[i] = r.e_measured_um[i] - r.e_predicted_um[i];
  const auto ls = evaluate_straightness(r.position_mm, d, {}, ReferenceLine::least_squares, opts);
  std::size_t inside = 0;
  for (std::size_t i = 0; i < r.points; ++i) {
    const double u = std::hypot(r.u_before_um[i], r.u_measured_um[i]);
    if (std::abs(d[i] - ls.line.at(r.position_mm[i])) <= opts.coverage_factor * u) ++inside;
  }
  r.pointwise_coverage = static_cast<double>(inside) / static_cast<double>(r.points);
  return r;
}

}  // namespace errsep::core

#include "errsep/core/step_decision.hpp"

#include <boost/math/distributions/fisher_f.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace errsep::core {

bool StepDecisionOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(max_error_ratio > 0 && max_error_ratio <= 1))
    return fail("max_error_ratio = " + std::to_string(max_error_ratio) + ": must be in (0, 1]");
  if (!(max_quantity_increase >= 0))
    return fail("max_quantity_increase = " + std::to_string(max_quantity_increase) +
                ": must be >= 0");
  if (!(bias_z >= 0 && std::isfinite(bias_z)))
    return fail("bias_z = " + std::to_string(bias_z) + ": must be finite and >= 0");
  return true;
}

const QuantityEffect* StepDecision::quantity(const std::string& name) const {
  for (const auto& q : quantities)
    if (q.name == name) return &q;
  return nullptr;
}

StepDecision decide_step(const Eigen::VectorXd& p, const Eigen::MatrixXd& cov,
                         const std::vector<QuantityImpact>& quantities,
                         const StepDecisionOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("step decision options: " + why);
  const Eigen::Index k = p.size();
  if (cov.rows() != k || cov.cols() != k)
    throw std::invalid_argument(
        "decide_step: covariance must be k x k for k = " + std::to_string(k) + " parameters");
  StepDecision d;
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(k, k);  // Σ_q D_qᵀ diag(1/u²) D_q over counted points
  bool any_too_bad = false;
  std::string worst;
  for (const auto& q : quantities) {
    if (q.sensitivity.cols() != k || q.sensitivity.rows() != q.u_base.size() ||
        (q.remainder.size() != 0 && q.remainder.size() != q.u_base.size()))
      throw std::invalid_argument("decide_step: quantity '" + q.name +
                                  "' needs an n x k sensitivity, n base uncertainties and an "
                                  "empty or n-point remainder");
    QuantityEffect e;
    e.name = q.name;
    e.unit = q.unit;
    const Eigen::VectorXd change = q.sensitivity * p;
    const Eigen::VectorXd var = (q.sensitivity * cov).cwiseProduct(q.sensitivity).rowwise().sum();
    // The linearisation's remainder: with the scatter in V (and in what applying adds to u), not
    // in B's variance correction.
    const Eigen::VectorXd rem2 = q.remainder.size() ? Eigen::VectorXd(q.remainder.array().square())
                                                    : Eigen::VectorXd::Zero(q.u_base.size());
    double n = 0, sv = 0, sb = 0, u2 = 0, c2 = 0, v2 = 0, b2 = 0;
    const double umax = q.u_base.size() ? q.u_base.maxCoeff() : 0.0;
    for (Eigen::Index i = 0; i < q.u_base.size(); ++i) {
      const double u = q.u_base(i);
      c2 += change(i) * change(i);
      v2 += var(i) + rem2(i);
      b2 += change(i) * change(i) - var(i);
      u2 += u * u;
      if (!(u > 1e-9 * umax) || !(u > 0)) continue;  // pinned by the gauge: no error to weigh
      n += 1;
      M += q.sensitivity.row(i).transpose() * q.sensitivity.row(i) / (u * u);
      sv += (var(i) + rem2(i)) / (u * u);
      sb += (change(i) * change(i) - var(i)) / (u * u);
    }
    const auto m = static_cast<double>(std::max<Eigen::Index>(1, q.u_base.size()));
    e.rms_u_base = std::sqrt(u2 / m);
    e.rms_change = std::sqrt(c2 / m);
    e.rms_added_u = std::sqrt(v2 / m);
    e.rms_bias = std::sqrt(std::max(0.0, b2 / m));
    e.expected_mse_ratio = n > 0 ? (n + sv) / (n + std::max(0.0, sb)) : 1.0;
    d.variance_sum += sv;
    d.bias_sum += sb;
    // Expected growth of this quantity's squared error if applied, in units of its noise.
    if (n > 0 && (sv - std::max(0.0, sb)) > opts.max_quantity_increase * n) {
      any_too_bad = true;
      if (!worst.empty()) worst += ", ";
      worst += q.name;
    }
    d.quantities.push_back(std::move(e));
  }
  {
    const Eigen::MatrixXd MC = M * cov;
    const double var_B = 4.0 * p.dot(MC * (M * p)) + 2.0 * (MC * MC).trace();
    d.bias_sd = std::sqrt(std::max(0.0, var_B));
  }
  d.bias_bound = d.bias_sum - opts.bias_z * d.bias_sd;
  char buf[240];
  if (!(d.bias_sum > 0)) {
    d.apply = false;
    std::snprintf(buf, sizeof buf,
                  "no bias detectable beyond the correction's own scatter (B = %.3g, V = %.3g)",
                  d.bias_sum, d.variance_sum);
  } else if (d.variance_sum > opts.max_error_ratio * d.bias_sum) {
    d.apply = false;
    std::snprintf(buf, sizeof buf,
                  "too poorly determined: its scatter V = %.3g is more than %.2g of the bias B = "
                  "%.3g it would remove",
                  d.variance_sum, opts.max_error_ratio, d.bias_sum);
  } else if (d.variance_sum > opts.max_error_ratio * d.bias_bound) {
    d.apply = false;
    std::snprintf(buf, sizeof buf,
                  "not clearly worth it: its scatter V = %.3g is more than %.2g of the bias it "
                  "would remove at its lower bound B - %.2g sd = %.3g - %.3g",
                  d.variance_sum, opts.max_error_ratio, opts.bias_z, d.bias_sum,
                  opts.bias_z * d.bias_sd);
  } else if (any_too_bad) {
    d.apply = false;
    std::snprintf(buf, sizeof buf, "it would make %s worse (V = %.3g, B = %.3g)", worst.c_str(),
                  d.variance_sum, d.bias_sum);
  } else {
    d.apply = true;
    std::snprintf(buf, sizeof buf,
                  "expected squared error %.2g of what it is without the correction (V = %.3g, "
                  "B = %.3g)",
                  d.variance_sum / d.bias_sum, d.variance_sum, d.bias_sum);
  }
  d.reason = buf;
  return d;
}

Eigen::VectorXd refined_uncertainty(const Eigen::VectorXd& u_sep, const Eigen::MatrixXd& D,
                                    const Eigen::MatrixXd& cov, const Eigen::VectorXd& p,
                                    const std::vector<bool>& applied) {
  const Eigen::Index K = p.size();
  if (D.rows() != u_sep.size() || D.cols() != K || cov.rows() != K || cov.cols() != K ||
      static_cast<Eigen::Index>(applied.size()) != K)
    throw std::invalid_argument("refined_uncertainty: inconsistent sizes");
  Eigen::VectorXd mask_a(K), mask_l(K);
  for (Eigen::Index j = 0; j < K; ++j) {
    mask_a(j) = applied[static_cast<std::size_t>(j)] ? 1.0 : 0.0;
    mask_l(j) = 1.0 - mask_a(j);
  }
  const Eigen::MatrixXd Da = D * mask_a.asDiagonal();
  const Eigen::VectorXd var = (Da * cov).cwiseProduct(Da).rowwise().sum();
  const Eigen::VectorXd bias = D * mask_l.cwiseProduct(p);
  return (u_sep.array().square() + var.array().max(0.0) + bias.array().square()).sqrt();
}

double f_test_p_value(double F, int k, int dof) {
  if (k <= 0 || dof <= 0 || !(F > 0)) return 1.0;
  const boost::math::fisher_f_distribution<double> dist(k, dof);
  return boost::math::cdf(boost::math::complement(dist, F));
}

std::string describe_decision(const std::string& effect, const std::vector<std::string>& names,
                              const Eigen::VectorXd& p, const Eigen::VectorXd& u_p,
                              const StepDecision& d) {
  std::string out = effect + (d.apply ? " applied (" : " detected (");
  char buf[200];
  for (Eigen::Index j = 0; j < p.size() && j < 6; ++j) {
    const std::string nm =
        static_cast<std::size_t>(j) < names.size() ? names[static_cast<std::size_t>(j)] : "p";
    std::snprintf(buf, sizeof buf, "%s%s = %.4g +- %.2g", j ? ", " : "", nm.c_str(), p(j),
                  j < u_p.size() ? u_p(j) : 0.0);
    out += buf;
  }
  if (p.size() > 6) out += ", ...";
  out += ")";
  const QuantityEffect* S = d.quantity("S");
  const QuantityEffect* lead = S ? S : (d.quantities.empty() ? nullptr : &d.quantities.front());
  if (d.apply) {
    if (lead) {
      std::snprintf(buf, sizeof buf, ": %s changed by %.3g %s rms, adds %.3g %s to u_%s",
                    lead->name.c_str(), lead->rms_change, lead->unit.c_str(), lead->rms_added_u,
                    lead->unit.c_str(), lead->name.c_str());
      out += buf;
    }
  } else {
    out += ": not applied";
    if (lead) {
      std::snprintf(buf, sizeof buf, ", adds %.3g %s to u_%s (rms, in quadrature)",
                    lead->rms_change, lead->unit.c_str(), lead->name.c_str());
      out += buf;
    }
  }
  return out + "; " + d.reason;
}

}  // namespace errsep::core

#include "errsep/core/gross_errors.hpp"

#include <Eigen/Cholesky>
#include <Eigen/SVD>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <stdexcept>

#include "errsep/core/refine.hpp"
#include "errsep/core/residual_trace.hpp"
#include "errsep/core/step_decision.hpp"

namespace errsep::core {

namespace {

// Standardised residuals |r_nc|/√d_nc of the valid readings (d_nc > tiny) and their MAD scale.
double robust_scale(const Eigen::MatrixXd& res, const Eigen::MatrixXd& d,
                    std::vector<double>* buf) {
  buf->clear();
  for (Eigen::Index n = 0; n < res.rows(); ++n)
    for (Eigen::Index i = 0; i < 4; ++i)
      if (d(n, i) > 1e-9) buf->push_back(std::abs(res(n, i)) / std::sqrt(d(n, i)));
  if (buf->empty()) return 0.0;
  auto mid = buf->begin() + static_cast<std::ptrdiff_t>(buf->size() / 2);
  std::nth_element(buf->begin(), mid, buf->end());
  return 1.4826 * *mid;
}

struct Candidates {
  // Spikes: readings with d > tiny; steps: normalised projected columns W (2P × S) and their
  // (configuration, first position).
  Eigen::MatrixXd W;
  std::vector<std::pair<int, int>> steps;
};

struct RoundStats {
  double spike = 0, step = 0;
  int spike_n = -1, spike_c = -1, step_j = -1;
  double sigma = 0;
  // The best rival of the other configurations: at the spike's position, and among the steps.
  double spike_rival = 0, step_rival = 0;
  // Per configuration: |t| of its reading at the spike's position, and its best step (|t|, the
  // candidate's index): where else the error may be.
  std::array<double, 4> spike_t{}, step_t{};
  std::array<int, 4> step_best_j{-1, -1, -1, -1};
  double rss = 0;
};

RoundStats round_statistics(const FourSensorConfig& cfg, const Eigen::VectorXd& r,
                            const Eigen::MatrixXd& d, const Candidates& cand, int dof,
                            std::vector<double>* buf) {
  RoundStats s;
  const Eigen::MatrixXd res = expand_residual(cfg, r);
  s.sigma = robust_scale(res, d, buf);
  if (!(s.sigma > 0)) return s;
  for (Eigen::Index n = 0; n < res.rows(); ++n)
    for (int i = 0; i < 4; ++i) {
      if (!(d(n, i) > 1e-9)) continue;
      const double t = std::abs(res(n, i)) / std::sqrt(d(n, i)) / s.sigma;
      if (t > s.spike) {
        s.spike = t;
        s.spike_n = static_cast<int>(n);
        s.spike_c = i;
      }
    }
  s.rss = r.squaredNorm();
  if (s.spike_n >= 0)
    for (int i = 0; i < 4; ++i) {
      if (!(d(s.spike_n, i) > 1e-9)) continue;
      s.spike_t[static_cast<std::size_t>(i)] =
          std::abs(res(s.spike_n, i)) / std::sqrt(d(s.spike_n, i)) / s.sigma;
      if (i != s.spike_c)
        s.spike_rival = std::max(s.spike_rival, s.spike_t[static_cast<std::size_t>(i)]);
    }
  if (cand.W.cols() > 0) {
    // The likelihood ratio of a change-point: |c_j| over σ̂ of the model with that step in it,
    // so the step does not inflate its own scale (a MAD would be: it moves most readings).
    const Eigen::VectorXd c = (cand.W.transpose() * r).cwiseAbs();
    Eigen::Index j = 0;
    const double cmax = c.maxCoeff(&j);
    const double rest = std::max(s.rss - cmax * cmax, 1e-300);
    const double sd = std::sqrt(rest / std::max(1, dof - 1));
    s.step = cmax / sd;
    s.step_j = static_cast<int>(j);
    const int cj = cand.steps[static_cast<std::size_t>(j)].first;
    for (Eigen::Index i = 0; i < c.size(); ++i) {
      const auto ci = static_cast<std::size_t>(cand.steps[static_cast<std::size_t>(i)].first);
      if (c(i) / sd > s.step_t[ci]) {
        s.step_t[ci] = c(i) / sd;
        s.step_best_j[ci] = static_cast<int>(i);
      }
      if (static_cast<int>(ci) != cj) s.step_rival = std::max(s.step_rival, c(i));
    }
    s.step_rival /= sd;
  }
  return s;
}

Eigen::VectorXd spike_column(int P, int n, int c) {
  Eigen::VectorXd z = Eigen::VectorXd::Zero(4 * P);
  z(4 * n + c) = 1.0;
  return z;
}

Eigen::VectorXd step_column(int P, int k, int c) {
  Eigen::VectorXd z = Eigen::VectorXd::Zero(4 * P);
  for (int n = k; n < P; ++n)
    z(4 * n + c) = 1.0;
  return z;
}

// A knocked sensor is a jump, a drift of one sensor over the traverse is smooth, yet the best
// change-point of a ramp or an exponential approach is near its middle and a step column fits it
// well.  The likelihood ratio of the step (its normalised projected column w) added to a model
// that already has a smooth drift of the same configuration: a cubic in position of that
// configuration's readings (within a traverse the time is affine in position, so a cubic in
// time), projected against `space` like the step.  In χ²₁ units with σ̂ of the model with both.
// A true step keeps most of its signal (a cubic takes 86 % of a mid-scan step's energy, less
// near the ends); a drift leaves the step nothing beyond noise.
double step_over_smooth(const FourSensorConfig& cfg, const ResidualSpace& space,
                        const Eigen::VectorXd& r, const Eigen::VectorXd& w, int configuration) {
  const int P = cfg.positions();
  const int c0 = configuration < 0 ? 0 : configuration, nc = configuration < 0 ? 4 : 1;
  Eigen::MatrixXd smooth = Eigen::MatrixXd::Zero(4 * P, 3 * nc);
  for (int c = c0; c < c0 + nc; ++c)
    for (int n = 0; n < P; ++n) {
      const double u = P > 1 ? 2.0 * n / (P - 1.0) - 1.0 : 0.0;
      const int j = 3 * (c - c0);
      smooth(4 * n + c, j) = u;
      smooth(4 * n + c, j + 1) = 1.5 * u * u - 0.5;
      smooth(4 * n + c, j + 2) = 2.5 * u * u * u - 1.5 * u;
    }
  const Eigen::MatrixXd Zs = space.project_out(reduce_columns(cfg, smooth));
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(Zs, Eigen::ComputeThinU);
  const Eigen::VectorXd& sv = svd.singularValues();
  Eigen::Index rank = 0;
  for (Eigen::Index j = 0; j < sv.size(); ++j)
    if (sv(j) > 1e-8 * std::max(1.0, sv(0))) ++rank;
  const Eigen::MatrixXd Q = svd.matrixU().leftCols(rank);
  const Eigen::VectorXd rs = r - Q * (Q.transpose() * r);
  const Eigen::VectorXd ws = w - Q * (Q.transpose() * w);
  if (!(ws.norm() > 1e-9 * w.norm())) return 0.0;  // the smooth model holds the step
  const double c = ws.dot(rs) / ws.norm();
  const int dof = space.dof() - static_cast<int>(rank) - 1;
  if (dof <= 0) return 0.0;
  const double s2 = std::max(rs.squaredNorm() - c * c, 1e-300) / dof;
  return c * c / s2;
}

Eigen::VectorXd error_column(GrossErrorKind kind, int P, int position, int configuration) {
  return kind == GrossErrorKind::spike ? spike_column(P, position, configuration)
                                       : step_column(P, position, configuration);
}

// The value exceeded by a fraction `level` of the draws.
double upper_quantile(std::vector<double> v, double level) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const auto k = static_cast<std::size_t>(
      std::clamp((1.0 - level) * static_cast<double>(v.size()), 0.0, double(v.size() - 1)));
  return v[k];
}

// The correction, the carried covariance and the report lines from the errors' applied flags.
std::string fmt(const char* f, double a, double b = 0, double c = 0) {
  char buf[200];
  std::snprintf(buf, sizeof buf, f, a, b, c);
  return buf;
}

void finish(GrossErrorScan* out, int P, double cfg_dx_mm, double attribution_chi2) {
  out->correction_um = Eigen::MatrixXd::Zero(P, 4);
  out->carried = out->covariance;
  out->findings.clear();
  for (std::size_t j = 0; j < out->errors.size(); ++j) {
    GrossError& e = out->errors[j];
    const auto c = static_cast<Eigen::Index>(j);
    if (e.applied) {
      for (int n = 0; n < P; ++n)
        for (int i = 0; i < 4; ++i)
          out->correction_um(n, i) += e.size_um * out->columns(4 * n + i, c);
    } else if (e.alternatives.size() <= 1) {
      // Left in: its size goes into u (the larger of this scan's fit and another measurement's).
      out->carried(c, c) += std::max(e.size_um * e.size_um, e.known_size_um * e.known_size_um);
    }  // else: carried through each plausible configuration's column (separate_without_...)
    char buf[900];
    std::string what =
        e.applied ? (e.kind == GrossErrorKind::spike ? "removed from the separation"
                                                     : "given its own offset in the separation")
                  : "NOT removed (" + e.not_applied + "): its size is in u_S";
    if (!e.applied && e.u_S_added_um > 0)
      what += fmt(" (widened by up to %.2g um)", e.u_S_added_um);
    if (e.smooth && e.alternatives.size() <= 1) {
      std::snprintf(buf, sizeof buf,
                    "change near x = %.4g mm (as a step of configuration %d: %+.3g +- %.2g um; z "
                    "= %.3g, p = %.2g), but a smooth drift of configuration %d explains it as well "
                    "(the step adds chi2 %.3g to a cubic in time): a drift, not a knocked sensor; "
                    "%s",
                    e.x_mm, e.configuration + 1, e.size_um, e.u_size_um, e.robust_z, e.p_value,
                    e.smooth_configuration + 1, e.step_over_smooth_chi2, what.c_str());
    } else if (e.alternatives.size() > 1) {
      // Ambiguous: say where it may be, each configuration with its own size and place.
      std::string where;
      for (std::size_t a = 0; a < e.alternatives.size(); ++a) {
        const GrossErrorAlternative& alt = e.alternatives[a];
        where +=
            (a ? (a + 1 == e.alternatives.size() ? " or " : ", ") : "") +
            fmt("%.0f (%+.3g +- %.2g um ", alt.configuration + 1.0, alt.size_um, alt.u_size_um) +
            fmt(e.kind == GrossErrorKind::spike ? "at x = %.4g mm)" : "from x = %.4g mm on)",
                alt.position * cfg_dx_mm);
      }
      std::snprintf(
          buf, sizeof buf,
          "%s near x = %.4g mm in one of the configurations %s; they explain it within "
          "chi2 %.3g of each other, so this scan cannot tell which (z = %.3g, p = %.2g); "
          "%s",
          e.kind == GrossErrorKind::spike ? "spike: one reading off" : "step: a knocked sensor",
          e.x_mm, where.c_str(), attribution_chi2, e.robust_z, e.p_value, what.c_str());
    } else if (e.kind == GrossErrorKind::spike)
      std::snprintf(buf, sizeof buf,
                    "spike: the reading of configuration %d at x = %.4g mm is off by %+.3g +- "
                    "%.2g um (robust z = %.3g, p = %.2g); %s",
                    e.configuration + 1, e.x_mm, e.size_um, e.u_size_um, e.robust_z, e.p_value,
                    what.c_str());
    else if (!e.attributed_by.empty())
      std::snprintf(buf, sizeof buf,
                    "step: configuration %d reads %+.3g +- %.2g um off from x = %.4g mm on (a "
                    "knocked sensor named by %s, which differ by %.3g um there; z = %.3g in this "
                    "scan alone); %s",
                    e.configuration + 1, e.size_um, e.u_size_um, e.x_mm, e.attributed_by.c_str(),
                    e.known_size_um, e.robust_z, what.c_str());
    else
      std::snprintf(buf, sizeof buf,
                    "step: configuration %d reads %+.3g +- %.2g um off from x = %.4g mm on "
                    "(a knocked sensor; z = %.3g, p = %.2g; better than a smooth drift by chi2 "
                    "%.3g); %s",
                    e.configuration + 1, e.size_um, e.u_size_um, e.x_mm, e.robust_z, e.p_value,
                    e.step_over_smooth_chi2, what.c_str());
    e.description = buf;
    out->findings.push_back(e.description);
  }
}

}  // namespace

const char* to_string(GrossErrorKind k) {
  return k == GrossErrorKind::spike ? "spike" : "step";
}

bool GrossErrorOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(alpha > 0 && alpha < 1))
    return fail("alpha = " + std::to_string(alpha) + ": must be in (0, 1)");
  if (max_errors < 0) return fail("max_errors = " + std::to_string(max_errors) + ": must be >= 0");
  if (!(apply_margin >= 0))
    return fail("apply_margin = " + std::to_string(apply_margin) + ": must be >= 0");
  if (!(smooth_chi2 >= 0))
    return fail("smooth_chi2 = " + std::to_string(smooth_chi2) + ": must be >= 0");
  if (!(attribution_chi2 >= 0))
    return fail("attribution_chi2 = " + std::to_string(attribution_chi2) + ": must be >= 0");
  if (min_segment < 1)
    return fail("min_segment = " + std::to_string(min_segment) + ": must be >= 1");
  if (cluster_positions < 0)
    return fail("cluster_positions = " + std::to_string(cluster_positions) + ": must be >= 0");
  // The smallest Monte-Carlo p-value is 1/(mc_samples + 1); it must reach α/2.
  if (static_cast<double>(mc_samples + 1) * 0.5 * alpha <= 1.0)
    return fail("mc_samples = " + std::to_string(mc_samples) +
                " cannot reach alpha/2 = " + std::to_string(0.5 * alpha));
  return true;
}

GrossErrorScan find_gross_errors(const ResidualSpace& space_in, const Eigen::MatrixXd& m_um,
                                 const GrossErrorOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("invalid gross error options: " + why);
  const FourSensorConfig& cfg = space_in.config();
  const int P = cfg.positions();
  if (m_um.rows() != P || m_um.cols() != 4)
    throw std::invalid_argument("find_gross_errors: readings must be P x 4");
  GrossErrorScan out;
  out.correction_um = Eigen::MatrixXd::Zero(P, 4);
  out.columns.resize(4 * P, 0);
  out.attribution_chi2 = opts.attribution_chi2;
  const Eigen::VectorXd y = reduce_readings(cfg, m_um);
  ResidualSpace space = space_in;
  std::vector<double> buf;
  std::mt19937_64 rng(opts.seed);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<std::pair<int, int>> spikes_found;
  // Steps another measurement names (repeat_steps.hpp) go into the model first, whether or not
  // this scan alone could find them: a step of configuration 4 is nearly fitted by γ and shows
  // little here, yet it moves S by its full size.
  for (const AttributedStep& a : opts.attributed_steps) {
    if (a.configuration < 0 || a.configuration > 3 || a.position < 1 || a.position >= P)
      throw std::invalid_argument("find_gross_errors: attributed step at configuration " +
                                  std::to_string(a.configuration) + ", position " +
                                  std::to_string(a.position) + " is outside the scan");
    const Eigen::VectorXd col = step_column(P, a.position, a.configuration);
    const Eigen::VectorXd zp = space.project_out(reduce_columns(cfg, Eigen::MatrixXd(col)));
    const Eigen::VectorXd r = space.project_out(y);
    if (space.add(reduce_columns(cfg, Eigen::MatrixXd(col))) == 0 || !(zp.norm() > 0)) continue;
    GrossError e;
    e.kind = GrossErrorKind::step;
    e.configuration = a.configuration;
    e.position = a.position;
    e.x_mm = a.position * cfg.dx_mm;
    const int dof = std::max(1, space.dof());
    const double c = zp.dot(r) / zp.norm();
    e.robust_z = std::abs(c) / std::sqrt(std::max(r.squaredNorm() - c * c, 1e-300) / dof);
    e.alternatives.push_back({a.configuration, a.position, 0.0, 0.0});
    e.attributed_by = a.by;
    e.known_size_um = std::abs(a.size_um);
    e.known_u_size_um = a.u_size_um;
    Eigen::MatrixXd C(4 * P, out.columns.cols() + 1);
    C << out.columns, col;
    out.columns = std::move(C);
    out.errors.push_back(e);
  }
  for (int round = 0; round < opts.max_errors && space.dof() > 2; ++round) {
    const Eigen::VectorXd r = space.project_out(y);
    const Eigen::MatrixXd d = reading_projector_diagonal(space);
    Candidates cand;
    {
      std::vector<Eigen::VectorXd> cols;
      for (int c = 0; c < 4; ++c)
        for (int k = opts.min_segment; k <= P - opts.min_segment; ++k) {
          const Eigen::VectorXd z = reduce_columns(cfg, step_column(P, k, c));
          const Eigen::VectorXd zp = space.project_out(z);
          if (zp.norm() <= 1e-6 * z.norm()) continue;  // the model already holds it
          cols.push_back(zp / zp.norm());
          cand.steps.emplace_back(c, k);
        }
      cand.W.resize(2 * P, static_cast<Eigen::Index>(cols.size()));
      for (std::size_t j = 0; j < cols.size(); ++j)
        cand.W.col(static_cast<Eigen::Index>(j)) = cols[j];
    }
    const RoundStats data = round_statistics(cfg, r, d, cand, space.dof(), &buf);
    if (!(data.sigma > 0)) break;
    if (round == 0) out.sigma_robust_um = data.sigma;
    int ge_spike = 0, ge_step = 0;
    double max_spike = 0, max_step = 0;
    std::vector<double> null_spike, null_step;
    Eigen::VectorXd z(2 * P);
    for (int s = 0; s < opts.mc_samples; ++s) {
      for (Eigen::Index j = 0; j < z.size(); ++j)
        z(j) = g(rng);
      const RoundStats st = round_statistics(cfg, space.project_out(z), d, cand, space.dof(), &buf);
      if (st.spike >= data.spike) ++ge_spike;
      if (st.step >= data.step) ++ge_step;
      max_spike = std::max(max_spike, st.spike);
      max_step = std::max(max_step, st.step);
      null_spike.push_back(st.spike);
      null_step.push_back(st.step);
    }
    const double p_spike = (1.0 + ge_spike) / (1.0 + opts.mc_samples);
    const double p_step = cand.W.cols() > 0 ? (1.0 + ge_step) / (1.0 + opts.mc_samples) : 1.0;
    const double level = 0.5 * opts.alpha;
    if (!(std::min(p_spike, p_step) < level)) break;
    GrossError e;
    Eigen::VectorXd col;
    // The smaller p first; on a tie (both at the Monte-Carlo floor) the larger excess over the
    // largest null draw of its own kind: a step spreads over many readings and also raises the
    // largest reading, a spike raises one reading far more than any step column.
    const bool spike =
        p_spike < p_step || (p_spike == p_step && data.spike / std::max(max_spike, 1e-300) >=
                                                      data.step / std::max(max_step, 1e-300));
    if (spike) {
      e.kind = GrossErrorKind::spike;
      e.configuration = data.spike_c;
      e.position = data.spike_n;
      e.robust_z = data.spike;
      e.p_value = p_spike;
      e.rival_z = data.spike_rival;
      e.z_critical = upper_quantile(null_spike, level);
      col = spike_column(P, data.spike_n, data.spike_c);
    } else {
      e.kind = GrossErrorKind::step;
      e.configuration = cand.steps[static_cast<std::size_t>(data.step_j)].first;
      e.position = cand.steps[static_cast<std::size_t>(data.step_j)].second;
      e.robust_z = data.step;
      e.p_value = p_step;
      e.rival_z = data.step_rival;
      e.z_critical = upper_quantile(null_step, level);
      col = step_column(P, e.position, e.configuration);
      // Against a smooth drift of any configuration: after the projection a drift of one
      // configuration can look like a step of another (a thermal drift of configuration 3 was
      // taken for a step of configuration 4: S 0.35 -> 1.89 um, errsep-refine-sweep seed 12).
      e.step_over_smooth_chi2 = std::numeric_limits<double>::infinity();
      for (int c = -1; c < 4; ++c) {
        const double chi2 = step_over_smooth(cfg, space, r, cand.W.col(data.step_j), c);
        if (chi2 < e.step_over_smooth_chi2) {
          e.step_over_smooth_chi2 = chi2;
          e.smooth_configuration = c;
        }
      }
      e.smooth = e.step_over_smooth_chi2 < opts.smooth_chi2;
    }
    e.x_mm = e.position * cfg.dx_mm;
    // Where else it may be: each configuration whose own best candidate of the same kind explains
    // the residual within attribution_chi2 of the best (likelihood ratio), the best first.
    e.alternatives.push_back({e.configuration, e.position, 0.0, 0.0});
    for (int c = 0; c < 4; ++c) {
      if (c == e.configuration) continue;
      const auto cu = static_cast<std::size_t>(c);
      const double t = spike ? data.spike_t[cu] : data.step_t[cu];
      if (t <= 0 || (!spike && data.step_best_j[cu] < 0)) continue;
      if (e.robust_z * e.robust_z - t * t >= opts.attribution_chi2) continue;
      const int pos =
          spike ? e.position : cand.steps[static_cast<std::size_t>(data.step_best_j[cu])].second;
      e.alternatives.push_back({c, pos, 0.0, 0.0});
    }
    // Which sensor position it was: the best candidate of another configuration must explain
    // clearly less (likelihood ratio of the two one-column models above χ²₁(0.99)); otherwise
    // the error is reported but not removed (removing the wrong one moves S by its full size).
    e.applied = e.alternatives.size() == 1 && !e.smooth;
    // Near the detection threshold the largest of many candidates is mostly the largest noise
    // (the winner's curse): its fitted size is inflated and removing it makes S worse.  Removed
    // only when the statistic clears the threshold by `apply_margin` (in its own units, ~σ).
    if (space.add(reduce_columns(cfg, col)) == 0) break;
    Eigen::MatrixXd C(4 * P, out.columns.cols() + 1);
    C << out.columns, col;
    out.columns = std::move(C);
    out.errors.push_back(e);
  }
  const auto K = out.columns.cols();
  const Eigen::VectorXd r0 = space_in.project_out(y);
  if (K == 0) {
    out.sigma_um = space_in.dof() > 0 ? std::sqrt(r0.squaredNorm() / space_in.dof()) : 0.0;
    return out;
  }
  // Joint fit of the sizes: r0 ≈ Π·Z·β (Π of the model without them).
  const Eigen::MatrixXd Zp = space_in.project_out(reduce_columns(cfg, out.columns));
  const Eigen::MatrixXd A = Zp.transpose() * Zp;
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(A);
  const Eigen::VectorXd beta = ldlt.solve(Zp.transpose() * r0);
  const int dof = space_in.dof() - static_cast<int>(K);
  const double s2 = dof > 0 ? (r0 - Zp * beta).squaredNorm() / dof : 0.0;
  out.sigma_um = std::sqrt(s2);
  out.covariance = s2 * ldlt.solve(Eigen::MatrixXd::Identity(K, K));
  for (Eigen::Index j = 0; j < K; ++j) {
    GrossError& e = out.errors[static_cast<std::size_t>(j)];
    e.size_um = beta(j);
    e.u_size_um = std::sqrt(std::max(0.0, out.covariance(j, j)));
    // Each alternative's own size: its column fitted to what the other errors leave.
    const Eigen::VectorXd rest = r0 - Zp * beta + Zp.col(j) * beta(j);
    for (std::size_t a = 0; a < e.alternatives.size(); ++a) {
      GrossErrorAlternative& alt = e.alternatives[a];
      if (a == 0) {
        alt.size_um = e.size_um;
        alt.u_size_um = e.u_size_um;
        continue;
      }
      const Eigen::VectorXd z = space_in.project_out(
          reduce_columns(cfg, error_column(e.kind, P, alt.position, alt.configuration)));
      alt.size_um = z.dot(rest) / z.squaredNorm();
      alt.u_size_um = std::sqrt(s2) / z.norm();
    }
    if (!e.attributed_by.empty()) {
      // Named by another measurement: the step is in the traverse this scan uses (size ±k, k
      // the known size) or in another traverse of that configuration (no step here); only this
      // scan tells which, and it can only when the two hypotheses lie far apart against its
      // uncertainty u (k >= 5u: choosing the nearer one then errs in < 1 % of scans).  Removed
      // when they do and |size| is nearer k than 0; otherwise left in, k bounding its bias.
      const double u = std::hypot(e.u_size_um, e.known_u_size_um);
      const double a = std::abs(e.size_um), k = e.known_size_um;
      e.applied = k >= 5.0 * u && std::abs(a - k) < a;
      if (!e.applied) {
        char b[300];
        std::snprintf(b, sizeof b,
                      "this scan cannot tell whether the knock fell in the traverse it uses "
                      "(a step of %.3g um) or in another one of the configuration (none here): "
                      "%+.3g +- %.2g um here",
                      e.known_size_um, e.size_um, e.u_size_um);
        e.not_applied = b;
      }
    } else if (e.smooth) {
      char b[200];
      std::snprintf(b, sizeof b,
                    "a smooth drift of configuration %d explains it as well: the step adds chi2 "
                    "%.3g < %.3g to a cubic in time, so not a knocked sensor",
                    e.smooth_configuration + 1, e.step_over_smooth_chi2, opts.smooth_chi2);
      e.not_applied = b;
    } else if (!e.applied)
      e.not_applied = e.kind == GrossErrorKind::spike
                          ? "another configuration's reading explains it almost as well"
                          : "a step of another configuration explains it almost as well";
    else if (e.robust_z < e.z_critical + opts.apply_margin) {
      e.applied = false;
      char b[160];
      std::snprintf(b, sizeof b,
                    "z = %.3g is within %.2g of the detection threshold %.3g: its size is not "
                    "determined",
                    e.robust_z, opts.apply_margin, e.z_critical);
      e.not_applied = b;
    }
  }
  // Runs of "spikes" along x.  An electrical spike hits one reading, independently of the
  // others; several found on one configuration within cluster_positions of each other are one
  // shape of that traverse (a local deformation, a bump in S while it ran: ΔS on one traverse,
  // refine_sweep's "bump"), which the spike column fits reading by reading.  Removing them took
  // the bump's readings out and left the rest of the bump in, with the fresh, lower σ̂ for the
  // shape: S worse (errsep-refine-sweep --plan single --effect bump, σ 0.05, seed 14: S 2.59 ->
  // 2.79 um, u_S 1.38 -> 1.21 um; σ 0.3 --size 3 seed 26: 2.51 -> 4.33 um).  Left in, their
  // fitted sizes go into u (finish: the bias of leaving an error in): seed 14 S 2.59 um (the raw
  // one), u_S 1.40; seed 26 S 2.51, u_S 7.5 (was 5.8).  Two independent spikes on
  // one configuration of P readings fall that close with probability about 2·cluster_positions/P
  // (7 % at P = 62): such a pair is carried in u instead of removed, which widens u, never
  // moves S.
  if (opts.cluster_positions > 0) {
    auto places = [](const GrossError& e) {
      std::vector<std::pair<int, int>> v;  // (configuration, position)
      if (e.alternatives.empty()) v.emplace_back(e.configuration, e.position);
      for (const auto& a : e.alternatives)
        v.emplace_back(a.configuration, a.position);
      return v;
    };
    std::vector<int> mates(out.errors.size(), 0);
    for (std::size_t i = 0; i < out.errors.size(); ++i)
      for (std::size_t j = i + 1; j < out.errors.size(); ++j) {
        if (out.errors[i].kind != GrossErrorKind::spike ||
            out.errors[j].kind != GrossErrorKind::spike)
          continue;
        bool near = false;
        for (const auto& a : places(out.errors[i]))
          for (const auto& b : places(out.errors[j]))
            near = near ||
                   (a.first == b.first && std::abs(a.second - b.second) <= opts.cluster_positions);
        if (near) {
          ++mates[i];
          ++mates[j];
        }
      }
    for (std::size_t i = 0; i < out.errors.size(); ++i) {
      GrossError& e = out.errors[i];
      if (mates[i] == 0 || !e.applied) continue;
      e.applied = false;
      char b[240];
      std::snprintf(b, sizeof b,
                    "%d other spike(s) of configuration %d within %d positions: a shape along x "
                    "during that traverse, not an electrical spike",
                    mates[i], e.configuration + 1, opts.cluster_positions);
      e.not_applied = b;
    }
  }
  finish(&out, P, cfg.dx_mm, opts.attribution_chi2);
  return out;
}

FourSensorResult separate_without_gross_errors(const FourSensorConfig& cfg,
                                               const Eigen::MatrixXd& m_um, GrossErrorScan* scan,
                                               const FourSensorResult& before,
                                               const FourSensorOptions& solve,
                                               const StepDecisionOptions& decision) {
  if (!scan || !scan->found()) return before;
  const int P = cfg.positions(), N = cfg.N;
  const auto K = scan->columns.cols();
  // Sensitivities to the sizes at before's λ: the correction −β·z is subtracted.
  const FourSensorOptions lin = linearised_options(before, solve);
  Eigen::MatrixXd D_S(P, K), D_g(P, K), D_f(N, K);
  for (Eigen::Index j = 0; j < K; ++j) {
    Eigen::MatrixXd c(P, 4);
    for (int n = 0; n < P; ++n)
      for (int i = 0; i < 4; ++i)
        c(n, i) = -scan->columns(4 * n + i, j);
    const FourSensorResult s = separate_four_sensor(cfg, c, lin);
    D_S.col(j) = s.S_um;
    D_g.col(j) = 1e6 * s.gamma_rad;
    D_f.col(j) = s.f_um;
  }
  D_S = remove_polynomial(D_S, 2);
  D_g = remove_polynomial(D_g, 1);
  // Removed only where that makes S, γ and f better (step_decision.hpp): a size the data
  // determine poorly (a step of configuration 4, whose readings γ nearly fits) is left in and
  // its fitted size goes into u instead.
  auto or_ones = [](const Eigen::VectorXd& u, Eigen::Index n) {
    return u.size() == n ? u : Eigen::VectorXd::Ones(n);
  };
  const Eigen::VectorXd uS = or_ones(before.u_S_um, P), ug = or_ones(1e6 * before.u_gamma_rad, P),
                        uf = or_ones(before.u_f_um, N);
  for (Eigen::Index j = 0; j < K; ++j) {
    GrossError& e = scan->errors[static_cast<std::size_t>(j)];
    if (!e.applied) continue;
    const std::vector<QuantityImpact> q = {{"S", "um", D_S.col(j), uS},
                                           {"gamma", "urad", D_g.col(j), ug},
                                           {"f", "um", D_f.col(j), uf}};
    const StepDecision d =
        decide_step(Eigen::VectorXd::Constant(1, e.size_um),
                    Eigen::MatrixXd::Constant(1, 1, scan->covariance(j, j)), q, decision);
    if (!d.apply) {
      e.applied = false;
      e.not_applied = d.reason;
    }
  }
  // An error left in whose configuration is ambiguous biases S by its true configuration's
  // column, which the scan cannot name: each plausible configuration's column with its own
  // fitted size is carried (the sum of their squares bounds the largest).
  std::vector<Eigen::VectorXd> aS, ag, af;
  std::vector<double> avar;
  for (GrossError& e : scan->errors) {
    e.u_S_added_um = 0;
    if (e.applied || e.alternatives.size() <= 1) continue;
    Eigen::VectorXd added = Eigen::VectorXd::Zero(P);
    for (const GrossErrorAlternative& alt : e.alternatives) {
      Eigen::MatrixXd c(P, 4);
      const Eigen::VectorXd z = error_column(e.kind, P, alt.position, alt.configuration);
      for (int n = 0; n < P; ++n)
        for (int i = 0; i < 4; ++i)
          c(n, i) = -z(4 * n + i);
      const FourSensorResult s = separate_four_sensor(cfg, c, lin);
      aS.push_back(remove_polynomial(s.S_um, 2));
      ag.push_back(remove_polynomial(1e6 * s.gamma_rad, 1));
      af.push_back(s.f_um);
      avar.push_back(alt.size_um * alt.size_um + alt.u_size_um * alt.u_size_um);
      added += (avar.back() * aS.back().array().square()).matrix();
    }
    e.u_S_added_um = std::sqrt(added.maxCoeff());
  }
  finish(scan, P, cfg.dx_mm, scan->attribution_chi2);
  const auto A = static_cast<Eigen::Index>(avar.size());
  Eigen::MatrixXd DS(P, K + A), Dg(P, K + A), Df(N, K + A);
  Eigen::MatrixXd carried = Eigen::MatrixXd::Zero(K + A, K + A);
  DS.leftCols(K) = D_S;
  Dg.leftCols(K) = D_g;
  Df.leftCols(K) = D_f;
  carried.topLeftCorner(K, K) = scan->carried;
  for (Eigen::Index a = 0; a < A; ++a) {
    const auto au = static_cast<std::size_t>(a);
    DS.col(K + a) = aS[au];
    Dg.col(K + a) = ag[au];
    Df.col(K + a) = af[au];
    carried(K + a, K + a) = avar[au];
  }
  FourSensorResult after = separate_four_sensor(cfg, m_um - scan->correction_um, solve);
  // The gauge of `before` (refine.hpp): the constant, line and bow of S, constant and line of γ.
  after.S_um = before.S_um + remove_polynomial(after.S_um - before.S_um, 2);
  after.gamma_rad = before.gamma_rad + remove_polynomial(after.gamma_rad - before.gamma_rad, 1);
  auto widen = [&](Eigen::VectorXd& u, const Eigen::MatrixXd& D, double scale) {
    if (u.size() != D.rows()) return;
    const Eigen::VectorXd var = (D * carried).cwiseProduct(D).rowwise().sum();
    u = (u.array().square() + (scale * scale) * var.array().max(0.0)).sqrt();
  };
  widen(after.u_S_um, DS, 1.0);
  widen(after.u_gamma_rad, Dg, 1e-6);
  widen(after.u_f_um, Df, 1.0);
  if (after.covariance) after.covariance->add_low_rank(DS, 1e-6 * Dg, Df, carried);
  return after;
}

}  // namespace errsep::core

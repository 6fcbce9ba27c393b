#include "errsep/core/refine.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <boost/math/distributions/fisher_f.hpp>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

namespace errsep::core {

bool RefineOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(alpha > 0 && alpha < 1))
    return fail("alpha = " + std::to_string(alpha) + ": must be in (0, 1)");
  if (max_effects < 0) return fail("max_effects must be >= 0");
  if (max_gauss_newton < 1) return fail("max_gauss_newton must be >= 1");
  if (!(gauss_newton_tolerance > 0)) return fail("gauss_newton_tolerance must be > 0");
  if (!(direction_threshold >= 0)) return fail("direction_threshold must be >= 0");
  if (!(identifiability_tol > 0 && identifiability_tol < 1))
    return fail("identifiability_tol must be in (0, 1)");
  if (!(speed_mm_per_s > 0)) return fail("speed_mm_per_s must be > 0");
  if (!solve.is_valid(why)) return false;
  return residual.is_valid(why);
}

namespace {

double rms_after_line(const Eigen::VectorXd& d) {
  const Eigen::Index n = d.size();
  if (n < 3) return 0.0;
  Eigen::MatrixXd A(n, 2);
  A.col(0).setOnes();
  A.col(1) = Eigen::VectorXd::LinSpaced(n, 0.0, 1.0);
  const Eigen::VectorXd c = A.colPivHouseholderQr().solve(d);
  return std::sqrt((d - A * c).squaredNorm() / static_cast<double>(n));
}

double p_value_F(double F, int k, int dof) {
  if (k <= 0 || dof <= 0) return 1.0;
  if (!(F > 0)) return 1.0;
  boost::math::fisher_f_distribution<double> dist(k, dof);
  return boost::math::cdf(boost::math::complement(dist, F));
}

// The least-squares (λ = 0) fit of the base model to corrected readings.
EffectContext ls_context(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_raw,
                         const Eigen::MatrixXd& m_c, const Eigen::MatrixXd& t_s,
                         const FourSensorOptions& solve) {
  // f̂, Ŝ, γ̂ for the corrections and Jacobians come from the caller's solver (its λ rule fixes
  // the non-identifiable curvature as the reported result does; the least-squares gauge row
  // would put a bow into f̂ and, through f̂(x+O+δ) − f̂(x+O), into the corrected readings).  The
  // residuals and tests never use them: they are projections of the readings.
  FourSensorOptions o = solve;
  o.compute_uncertainty = false;
  const FourSensorResult r = separate_four_sensor(cfg, m_c, o);
  EffectContext ctx;
  ctx.cfg = cfg;
  ctx.m_um = m_raw;
  ctx.t_s = t_s;
  ctx.f_um = r.f_um;
  ctx.S_um = r.S_um;
  ctx.gamma_rad = r.gamma_rad;
  ctx.e_um = r.e_um;
  ctx.residual_um = r.sensor_residual_um;
  ctx.prepare();
  return ctx;
}

struct Model {
  std::vector<std::shared_ptr<const ModelEffect>> effects;
  std::vector<Eigen::VectorXd> p;
  int total() const {
    int k = 0;
    for (const auto& e : effects)
      k += e->parameter_count();
    return k;
  }
};

Eigen::VectorXd concat(const Model& M) {
  Eigen::VectorXd v(M.total());
  Eigen::Index c = 0;
  for (const auto& p : M.p) {
    v.segment(c, p.size()) = p;
    c += p.size();
  }
  return v;
}

Eigen::MatrixXd corrected(const Model& M, const EffectContext& ctx) {
  Eigen::MatrixXd m = ctx.m_um;
  for (std::size_t j = 0; j < M.effects.size(); ++j)
    m -= M.effects[j]->correction_um(M.p[j], ctx);
  return m;
}

Eigen::MatrixXd model_jacobian(const Model& M, const EffectContext& ctx) {
  const Eigen::Index rows = 4 * ctx.m_um.rows();
  Eigen::MatrixXd J(rows, M.total());
  Eigen::Index c = 0;
  for (std::size_t j = 0; j < M.effects.size(); ++j) {
    const Eigen::MatrixXd Jj = M.effects[j]->jacobian(M.p[j], ctx);
    J.middleCols(c, Jj.cols()) = Jj;
    c += Jj.cols();
  }
  return J;
}

// Least-squares step on projected columns with the identifiable directions only.  Columns are
// scaled to unit norm (effects mix units: gains, mm, µm/s) and the step is taken along the right
// singular vectors of the projected, scaled columns.  With `p_current` (Gauss–Newton), a direction
// is kept only when the total parameter's signal along it, |c_j + s_j·v_jᵀp̃|, exceeds
// kappa·σ̂: a direction the data barely determine would otherwise put its large uncertainty into
// the corrected readings and from there into S, γ and f; such a direction is set to zero.
struct ProjectedFit {
  Eigen::VectorXd dp;
  Eigen::MatrixXd cov_unit;    // (JᵀRJ)⁺ on the kept directions, parameter units
  Eigen::MatrixXd directions;  // k × kept: orthonormal basis of the determined combinations
  Eigen::VectorXd relative_sv;
  double delta_rss = 0;
  int identifiable = 0;  // structurally identifiable directions
  int kept = 0;          // directions kept after the significance truncation
};

ProjectedFit projected_fit(const ResidualSpace& base, const Eigen::MatrixXd& Jr,
                           const Eigen::VectorXd& r, double tol,
                           const Eigen::VectorXd* p_current = nullptr, double kappa = 0.0) {
  ProjectedFit out;
  const Eigen::Index k = Jr.cols();
  out.dp = Eigen::VectorXd::Zero(k);
  out.cov_unit = Eigen::MatrixXd::Zero(k, k);
  if (k == 0) return out;
  Eigen::MatrixXd RJ = base.project_out(Jr);
  Eigen::VectorXd D(k);
  for (Eigen::Index c = 0; c < k; ++c) {
    D(c) = Jr.col(c).norm();
    if (!(D(c) > 0)) D(c) = 1.0;
    RJ.col(c) /= D(c);
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(RJ, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::VectorXd& sv = svd.singularValues();
  out.relative_sv = sv;
  int kid = 0;
  for (Eigen::Index j = 0; j < sv.size(); ++j)
    if (sv(j) > tol) ++kid;
  out.identifiable = kid;
  // σ̂ from the fit with all identifiable directions.
  Eigen::VectorXd c(kid);
  double fit_all = 0;
  for (int j = 0; j < kid; ++j) {
    c(j) = svd.matrixU().col(j).dot(r);
    fit_all += c(j) * c(j);
  }
  const int dof = base.dof() - kid;
  const double sigma = dof > 0 ? std::sqrt(std::max(0.0, r.squaredNorm() - fit_all) / dof) : 0.0;
  Eigen::VectorXd dps = Eigen::VectorXd::Zero(k);  // scaled step
  Eigen::VectorXd ps = Eigen::VectorXd::Zero(k);
  if (p_current) ps = p_current->cwiseProduct(D);
  std::vector<int> kept, free_dirs;
  for (int j = 0; j < kid; ++j) {
    const Eigen::VectorXd v = svd.matrixV().col(j);
    const double total = c(j) + sv(j) * v.dot(ps);  // signal of the whole parameter along v
    if (p_current && std::abs(total) <= kappa * sigma) {
      free_dirs.push_back(j);
      continue;
    }
    kept.push_back(j);
    dps += v * (c(j) / sv(j));
    out.delta_rss += c(j) * c(j);
  }
  // Directions the significance rule dropped are taken out of the parameters (scaled metric).
  for (int j : free_dirs)
    dps -= svd.matrixV().col(j) * svd.matrixV().col(j).dot(ps + dps);
  // Directions no data can determine (absorbed by f, S, γ, e, e.g. a drift common to all
  // configurations): the estimate is the part of p orthogonal to them in parameter units, so a
  // true p orthogonal to them is recovered and the report's "identifiable part" is well defined.
  if (p_current && kid < svd.matrixV().cols()) {
    const Eigen::Index k0 = svd.matrixV().cols() - kid;
    Eigen::MatrixXd Z = D.cwiseInverse().asDiagonal() * svd.matrixV().rightCols(k0);
    Eigen::HouseholderQR<Eigen::MatrixXd> zq(Z);
    Z = zq.householderQ() * Eigen::MatrixXd::Identity(k, k0);
    Eigen::VectorXd p_new = (ps + dps).cwiseQuotient(D);
    p_new -= Z * (Z.transpose() * p_new);
    dps = p_new.cwiseProduct(D) - ps;
  }
  out.kept = static_cast<int>(kept.size());
  out.dp = dps.cwiseQuotient(D);
  Eigen::MatrixXd B(k, out.kept);  // D⁻¹·v_j / s_j
  for (int q = 0; q < out.kept; ++q) {
    const int j = kept[static_cast<std::size_t>(q)];
    B.col(q) = svd.matrixV().col(j).cwiseQuotient(D) / sv(j);
  }
  out.cov_unit = B * B.transpose();
  // Determined combinations ℓᵀp: the row space of the kept part, orthonormal in parameter units.
  if (out.kept > 0) {
    Eigen::MatrixXd W(k, out.kept);
    for (int q = 0; q < out.kept; ++q)
      W.col(q) = svd.matrixV().col(kept[static_cast<std::size_t>(q)]).cwiseQuotient(D);
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(W);
    out.directions = qr.householderQ() * Eigen::MatrixXd::Identity(k, out.kept);
  } else {
    out.directions.resize(k, 0);
  }
  return out;
}

struct Solved {
  EffectContext ctx;
  Eigen::MatrixXd m_c;
  ResidualSpace space;
  double rss = 0;
  int iterations = 0;
  std::vector<Eigen::VectorXd> u;
  ProjectedFit last;  // the final linearisation (covariance, directions) of all parameters
  double s2 = 0;
};

// Gauss–Newton on the model's effect parameters with the base unknowns eliminated.
Solved solve_model(const FourSensorConfig& cfg, Model& M, EffectContext ctx,
                   const RefineOptions& opts) {
  const ResidualSpace base(cfg);
  const int k = M.total();
  int it = 0, halvings = 0;
  double rss_prev = std::numeric_limits<double>::infinity();
  Eigen::VectorXd step = Eigen::VectorXd::Zero(k);
  auto add_to_params = [&M](const Eigen::VectorXd& d) {
    Eigen::Index c = 0;
    for (auto& p : M.p) {
      p += d.segment(c, p.size());
      c += p.size();
    }
  };
  for (; it < (k > 0 ? opts.max_gauss_newton : 0); ++it) {
    const Eigen::MatrixXd m_c = corrected(M, ctx);
    const EffectContext trial = ls_context(cfg, ctx.m_um, m_c, ctx.t_s, opts.solve);
    const Eigen::VectorXd r = base.project_out(reduce_readings(cfg, m_c));
    const double rss = r.squaredNorm();
    // Step control: a step that increases the residual is halved (at most 8 times).
    if (rss > rss_prev * (1.0 + 1e-9) && halvings < 8) {
      step *= 0.5;
      add_to_params(-step);
      ++halvings;
      continue;
    }
    halvings = 0;
    rss_prev = rss;
    ctx = trial;
    const Eigen::MatrixXd Jr = reduce_columns(cfg, model_jacobian(M, ctx));
    const Eigen::VectorXd p_now = concat(M);
    const ProjectedFit fit =
        projected_fit(base, Jr, r, opts.identifiability_tol, &p_now, opts.direction_threshold);
    const int dof = base.dof() - fit.kept;
    const double s2 = dof > 0 ? (rss - fit.delta_rss) / dof : 0.0;
    bool converged = true;
    for (Eigen::Index j = 0; j < k; ++j) {
      const double u = std::sqrt(std::max(0.0, s2 * fit.cov_unit(j, j)));
      const double scale = std::max({u, 1e-9 * std::abs(p_now(j)), 1e-300});
      if (std::abs(fit.dp(j)) > opts.gauss_newton_tolerance * scale) converged = false;
    }
    step = fit.dp;
    add_to_params(step);
    if (converged) {
      ++it;
      break;
    }
  }
  Solved out{ctx, {}, ResidualSpace(cfg), 0.0, it, {}, {}, 0.0};
  out.m_c = corrected(M, ctx);
  out.ctx = ls_context(cfg, ctx.m_um, out.m_c, ctx.t_s, opts.solve);
  const Eigen::MatrixXd Jr = reduce_columns(cfg, model_jacobian(M, out.ctx));
  const Eigen::VectorXd r = base.project_out(reduce_readings(cfg, out.m_c));
  const Eigen::VectorXd p_now = concat(M);
  const ProjectedFit fit =
      projected_fit(base, Jr, r, opts.identifiability_tol, &p_now, opts.direction_threshold);
  out.space.add(Jr * fit.directions, opts.identifiability_tol);
  out.rss = out.space.project_out(reduce_readings(cfg, out.m_c)).squaredNorm();
  const double s2 = out.space.dof() > 0 ? out.rss / out.space.dof() : 0.0;
  out.last = fit;
  out.s2 = s2;
  Eigen::Index c = 0;
  for (const auto& p : M.p) {
    Eigen::VectorXd u(p.size());
    for (Eigen::Index j = 0; j < p.size(); ++j)
      u(j) = std::sqrt(std::max(0.0, s2 * fit.cov_unit(c + j, c + j)));
    out.u.push_back(u);
    c += p.size();
  }
  return out;
}

struct Scored {
  CandidateScore score;
  std::shared_ptr<const ModelEffect> variant;
  Eigen::VectorXd p0;
};

std::vector<Scored> score_candidates(const FourSensorConfig& cfg, const Solved& cur,
                                     const std::vector<std::unique_ptr<ModelEffect>>& library,
                                     const Model& M, const RefineOptions& opts,
                                     const std::vector<std::string>& excluded) {
  std::vector<Scored> out;
  const Eigen::VectorXd r = cur.space.project_out(reduce_readings(cfg, cur.m_c));
  const double rss = r.squaredNorm();
  for (const auto& eff : library) {
    bool present = false;
    for (const auto& e : M.effects)
      present = present || e->name() == eff->name();
    for (const auto& x : excluded)
      present = present || x == eff->name();
    if (present) continue;
    Scored best;
    best.score.effect = eff->name();
    best.score.description = eff->description();
    best.score.parameters = eff->parameter_count();
    best.score.trials = eff->effective_trials(cur.ctx);
    double best_F = -1;
    for (auto& v : eff->variants(cur.ctx)) {
      const Eigen::VectorXd p0 = Eigen::VectorXd::Zero(v->parameter_count());
      const Eigen::MatrixXd Jr = reduce_columns(cfg, v->jacobian(p0, cur.ctx));
      const ProjectedFit fit = projected_fit(cur.space, Jr, r, opts.identifiability_tol);
      const int dof = cur.space.dof() - fit.identifiable;
      if (fit.identifiable == 0 || dof <= 0) continue;
      const double F = (fit.delta_rss / fit.identifiable) / ((rss - fit.delta_rss) / dof);
      if (F > best_F) {
        best_F = F;
        best.score.description = v->description();
        best.score.identifiable = fit.identifiable;
        best.score.F = F;
        best.score.delta_rss_um2 = fit.delta_rss;
        best.score.relative_sv = fit.relative_sv;
        best.score.p_value = p_value_F(F, fit.identifiable, dof);
        best.variant = std::shared_ptr<const ModelEffect>(v->clone());
        best.p0 = fit.dp;
      }
    }
    // Šidák: probability that the best of M independent tries is at least this good.
    if (best.variant && best.score.trials > 1)
      best.score.p_value = -std::expm1(best.score.trials * std::log1p(-best.score.p_value));
    out.push_back(std::move(best));
  }
  return out;
}

}  // namespace

ProfileErrors profile_errors(const FourSensorResult& r, const RefineTruth& truth) {
  ProfileErrors e;
  if (truth.S_um.size() == r.S_um.size()) e.S_um = rms_after_line(r.S_um - truth.S_um);
  if (truth.gamma_rad.size() == r.gamma_rad.size()) {
    const Eigen::VectorXd d = r.gamma_rad - truth.gamma_rad;
    e.gamma_urad = 1e6 * std::sqrt((d.array() - d.mean()).square().mean());
  }
  if (truth.f_um.size() == r.f_um.size()) e.f_um = rms_after_line(r.f_um - truth.f_um);
  return e;
}

std::string RefineResult::brief_report() const {
  char buf[512];
  const RefineStep& last = steps.back();
  std::snprintf(buf, sizeof buf,
                "refine: model %s, %zu effect(s) added, residual RMS %.4g -> %.4g um, sigma_hat "
                "%.3g um (dof %d), residual %s (whiteness p = %.3g); %s",
                model_name.c_str(), effects.size(), steps.front().rms_after_um, last.rms_after_um,
                residual.sigma_um, residual.dof, residual_white() ? "white" : "NOT WHITE",
                residual.whiteness.p_value, stop_reason.c_str());
  std::string out = buf;
  if (!residual_white() && !residual.whiteness.rejected_by.empty())
    out += "; rejected by: " + residual.whiteness.rejected_by;
  for (const auto& rc : rejected)
    out += "; " + rc.effect + " " + rc.reason;
  for (const auto& k : implausible_kept)
    out += "; " + k;
  if (!model_complete()) out += "; model incomplete";
  return out;
}

RefineResult refine_four_sensor(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                                const Eigen::MatrixXd& t_s_in, const RefineOptions& opts,
                                const RefineTruth* truth,
                                std::vector<std::unique_ptr<ModelEffect>> library) {
  std::string why;
  if (!cfg.is_valid(&why)) throw std::invalid_argument("invalid configuration: " + why);
  if (!opts.is_valid(&why)) throw std::invalid_argument("invalid refine options: " + why);
  const int P = cfg.positions();
  if (m_um.rows() != P || m_um.cols() != 4)
    throw std::invalid_argument("readings must be P x 4 = " + std::to_string(P) + " x 4, got " +
                                std::to_string(m_um.rows()) + " x " + std::to_string(m_um.cols()));
  if (!m_um.allFinite()) throw std::invalid_argument("readings contain non-finite values");
  const Eigen::MatrixXd t_s =
      t_s_in.size() == 0 ? scan_order_times_s(cfg, opts.speed_mm_per_s) : t_s_in;
  if (t_s.rows() != P || t_s.cols() != 4 || !t_s.allFinite())
    throw std::invalid_argument("reading times must be a finite P x 4 matrix like the readings");
  if (library.empty()) library = default_effect_library();

  RefineResult res;
  res.t_s = t_s;
  res.model_name = "zhao2019-eq1";
  res.alpha_per_candidate = opts.alpha / static_cast<double>(library.size());
  res.alpha_residual = opts.residual.alpha;

  Model M;
  Solved cur = solve_model(cfg, M, ls_context(cfg, m_um, m_um, t_s, opts.solve), opts);
  res.before = separate_four_sensor(cfg, m_um, opts.solve);
  FourSensorResult current_sep = res.before;
  auto analyse = [&](const Solved& s) {
    return analyse_residual(s.space, s.m_c, t_s, opts.residual);
  };
  {
    RefineStep st;
    st.description = "Zhao 2019 Eq. (1): f, S, gamma, e (least squares, whitened rows)";
    st.rss_before_um2 = st.rss_after_um2 = cur.rss;
    st.rms_before_um = st.rms_after_um = std::sqrt(cur.rss / (4.0 * P));
    const ResidualAnalysis ra = analyse(cur);
    st.dof_after = ra.dof;
    st.sigma_after_um = ra.sigma_um;
    st.whiteness_after = ra.whiteness;
    st.dominant_period_mm = ra.dominant_period_mm;
    if (truth) st.error_before = st.error_after = profile_errors(res.before, *truth);
    res.steps.push_back(std::move(st));
    res.residual = ra;
  }

  // Physical plausibility.  An effect added in one round may fit with implausible parameters
  // only because another effect is still missing (PE1 with a periodic positioning error present
  // fits dD4 ~ 9 mm alone, 0.6 mm once the periodic error is in), so an addition is tentative:
  // the verdict is on the parameters of the joint model when the loop stops.  If an effect is
  // still implausible then, the loop goes back to the last model whose effects were all
  // plausible, records the implausible ones as rejected, and continues without them.
  struct Snapshot {
    Model M;
    Solved cur;
    std::size_t steps = 0;
    FourSensorResult sep;
    ResidualAnalysis residual;
    std::string model_name;
  };
  auto implausibility_of = [&](const Model& model, const EffectContext& ctx, std::size_t e) {
    return model.effects[e]->implausibility(model.p[e], ctx);
  };
  Snapshot plausible{M, cur, res.steps.size(), current_sep, res.residual, res.model_name};
  std::vector<std::string> excluded;  // rejected as implausible: not scored again
  for (std::size_t rollbacks = 0;; ++rollbacks) {
    res.stop_reason = "no candidate significant";
    while (true) {
      if (static_cast<int>(M.effects.size()) >= opts.max_effects) {
        res.stop_reason = "maximum number of effects reached";
        break;
      }
      std::vector<Scored> scores = score_candidates(cfg, cur, library, M, opts, excluded);
      std::vector<CandidateScore> table;
      const Scored* best = nullptr;
      for (const auto& s : scores) {
        table.push_back(s.score);
        if (s.variant && (!best || s.score.p_value < best->score.p_value)) best = &s;
      }
      // Threshold: α split over the candidates of this round (Bonferroni).
      const double threshold =
          opts.alpha / static_cast<double>(std::max<std::size_t>(1, scores.size()));
      if (!best || best->score.p_value >= threshold) {
        res.final_round = std::move(table);
        res.stop_reason = scores.empty() ? "library exhausted" : "no candidate significant";
        break;
      }
      RefineStep st;
      st.index = static_cast<int>(res.steps.size());
      st.effect = best->score.effect;
      st.description = best->variant->description();
      st.parameter_names = best->variant->parameter_names();
      st.F = best->score.F;
      st.p_value = best->score.p_value;
      st.identifiable = best->score.identifiable;
      st.relative_sv = best->score.relative_sv;
      st.rss_before_um2 = cur.rss;
      st.rms_before_um = std::sqrt(cur.rss / (4.0 * P));
      st.candidates = std::move(table);
      const std::vector<Eigen::VectorXd> p_saved = M.p;  // the joint re-solve moves them all
      M.effects.push_back(best->variant);
      M.p.push_back(best->p0);
      Solved next = solve_model(cfg, M, cur.ctx, opts);
      if (!(next.rss < cur.rss)) {
        // The linearised score promised a reduction the non-linear re-solve did not deliver.
        M.effects.pop_back();
        M.p = p_saved;
        res.final_round = std::move(st.candidates);
        res.stop_reason = "Gauss-Newton for '" + st.effect + "' did not reduce the residual";
        break;
      }
      cur = std::move(next);
      st.gauss_newton_iterations = cur.iterations;
      st.parameters = M.p.back();
      st.u_parameters = cur.u.back();
      {
        // The added effect's block of the joint linearisation.
        const Eigen::Index k = st.parameters.size(), c0 = M.total() - k;
        st.covariance = cur.s2 * cur.last.cov_unit.block(c0, c0, k, k);
        // The determined combinations of this effect's parameters: the part of the joint
        // directions' basis in its block, orthonormalised.
        const Eigen::MatrixXd Wb = cur.last.directions.middleRows(c0, k);
        Eigen::JacobiSVD<Eigen::MatrixXd> ws(Wb, Eigen::ComputeThinU);
        int kid = 0;
        for (Eigen::Index j = 0; j < ws.singularValues().size(); ++j)
          if (ws.singularValues()(j) > 1e-8) ++kid;
        st.identifiable_directions = ws.matrixU().leftCols(kid);
        st.identifiable = kid;
      }
      st.rss_after_um2 = cur.rss;
      st.rms_after_um = std::sqrt(cur.rss / (4.0 * P));
      const ResidualAnalysis ra = analyse(cur);
      st.dof_after = ra.dof;
      st.sigma_after_um = ra.sigma_um;
      st.whiteness_after = ra.whiteness;
      st.dominant_period_mm = ra.dominant_period_mm;
      const FourSensorResult sep = separate_four_sensor(cfg, cur.m_c, opts.solve);
      if (truth) {
        st.error_before = profile_errors(current_sep, *truth);
        st.error_after = profile_errors(sep, *truth);
      }
      current_sep = sep;
      res.residual = ra;
      res.model_name += "+" + st.effect;
      res.steps.push_back(std::move(st));
      bool all_plausible = true;
      for (std::size_t e = 0; e < M.effects.size(); ++e)
        all_plausible = all_plausible && implausibility_of(M, cur.ctx, e).empty();
      if (all_plausible)
        plausible = Snapshot{M, cur, res.steps.size(), current_sep, res.residual, res.model_name};
    }
    // The verdict on the joint model's parameters.
    std::vector<std::size_t> bad;
    for (std::size_t e = 0; e < M.effects.size(); ++e)
      if (!implausibility_of(M, cur.ctx, e).empty()) bad.push_back(e);
    if (bad.empty()) break;
    if (res.stop_reason == "maximum number of effects reached") {
      // The caller capped the model below what the data need: the effects in it stand in for the
      // missing ones.  They stay (the caller asked for this many), flagged, and the verdict is
      // "incomplete".
      for (std::size_t e : bad)
        res.implausible_kept.push_back(M.effects[e]->name() + ": implausible parameters (" +
                                       implausibility_of(M, cur.ctx, e) +
                                       "), kept because the loop was capped at max_effects");
      break;
    }
    // Reject the most recently added implausible effect: it was added on top of the others and
    // is the likeliest stand-in for what is missing (an earlier one may become plausible once it
    // is gone, as PE1 does when a spurious gain is removed).  One per rollback, so the loop ends.
    const std::size_t e = bad.back();
    {
      RejectedCandidate rc;
      rc.round = static_cast<int>(e);
      rc.effect = M.effects[e]->name();
      rc.description = M.effects[e]->description();
      rc.parameter_names = M.effects[e]->parameter_names();
      rc.parameters = M.p[e];
      rc.u_parameters = cur.u[e];
      const std::size_t si = e + 1;  // steps[0] is the base model
      if (si < res.steps.size()) {
        rc.F = res.steps[si].F;
        rc.p_value = res.steps[si].p_value;
      }
      rc.reason = "rejected: implausible parameters (" + implausibility_of(M, cur.ctx, e) + ")";
      res.rejected.push_back(std::move(rc));
      excluded.push_back(M.effects[e]->name());
    }
    // An effect already in the plausible snapshot cannot be removed by going back to it; then
    // exclude the first effect added after the snapshot as well.
    if (e < plausible.M.effects.size() && plausible.M.effects.size() < M.effects.size())
      excluded.push_back(M.effects[plausible.M.effects.size()]->name());
    M = plausible.M;
    cur = plausible.cur;
    res.steps.resize(plausible.steps);
    current_sep = plausible.sep;
    res.residual = plausible.residual;
    res.model_name = plausible.model_name;
    if (rollbacks + 1 >= library.size()) {
      res.stop_reason = "implausible effects rejected until the library was exhausted";
      break;
    }
  }
  res.effects = M.effects;
  res.parameters = M.p;
  res.u_parameters = cur.u;
  res.m_corrected_um = cur.m_c;
  res.after = M.effects.empty() ? res.before : current_sep;
  return res;
}

}  // namespace errsep::core

#include "errsep/core/refine.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <tuple>

namespace errsep::core {

// bias_z = 2 with no correction applied for an effect this plan cannot identify
// (RefineOptions::apply_unidentifiable off) is the default since stop 26 (issue 16 item 1).
// errsep-refine-sweep, seeds 1-20, 12 effects x sigma 0.05/0.1/0.2 (720 runs): with both, 3 runs
// were made worse beyond their u: PE2 at 0.2 um (a wrong minimum, c2 = 3094 +- 540 for 795,
// applied), a thermal drift taken for a knocked sensor by the gross-error search, a bump (not in
// the library); with bias_z = 0 and the undetermined part applied, 19 (clean data 2, PE1 7, PE2 2,
// thermal drift 4, non-linearity 3, bump 1), and applying the determined part of a drift, thermal
// drift or non-repeating traverse of one scan made S or gamma worse in 35-80 % of those runs;
// bias_z = 1 let a fit to clean noise through (worst gamma error 10.6 -> 24 urad).  The price:
// fewer halvings (gain 0.25 -> 0.15 of the runs at 0.05 um, PE1 0.10 -> 0.05 at 0.1 um) and none of
// a thermal drift on all configurations (0.35 at 0.05 um), which one scan cannot identify.
// Issue 16, stop 27 (errsep-refine-sweep, same 720 runs): gating a correction on
// effect_identifiability (RefineOptions::apply_requires_identifiable) stops the PE2 run above
// (its least-squares minimum is the global one, so more starts would not help) but also 12
// halvings elsewhere and the low-noise corrections of core/refine_effects: off by default.
// Coverage where the plan cannot see the effect: in the runs where nothing is added the effect's
// candidate scores like noise (p 0.06-0.95 for gain, 0.35-0.93 for a drift of one configuration,
// residual white), so no data-driven widening (sigma-hat already scales u: a Birge ratio is in it)
// can tell them from clean runs; RefineOptions::declared carries a declared bound instead.
StepDecisionOptions refine_step_decision() {
  StepDecisionOptions o;
  o.bias_z = 2.0;
  return o;
}

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
  if (!(reading_bound >= 0 && std::isfinite(reading_bound)))
    return fail("reading_bound = " + std::to_string(reading_bound) + ": must be finite and >= 0");
  for (const auto& d : declared) {
    if (!(d.bound > 0 && std::isfinite(d.bound)))
      return fail("declared bound of '" + d.effect + "' = " + std::to_string(d.bound) +
                  ": must be finite and > 0");
    bool known = false;
    std::string names;
    for (const auto& e : default_effect_library()) {
      known = known || e->name() == d.effect;
      names += (names.empty() ? "" : ", ") + e->name();
    }
    if (!known)
      return fail("declared bound for unknown effect '" + d.effect + "' (the library has " + names +
                  ")");
  }
  if (!solve.is_valid(why)) return false;
  if (!decision.is_valid(why)) return false;
  if (!trace.is_valid(why)) return false;
  if (!gross.is_valid(why)) return false;
  return residual.is_valid(why);
}

namespace {
// An orthonormal basis (n × min(degree+1, n)) of the polynomials of up to `degree` on n equally
// spaced points (Legendre-like abscissae in [-1, 1] for conditioning).
Eigen::MatrixXd polynomial_basis(Eigen::Index n, int degree) {
  const Eigen::Index m = std::min<Eigen::Index>(degree + 1, n);
  Eigen::MatrixXd B(n, m);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double t = n > 1 ? 2.0 * static_cast<double>(i) / static_cast<double>(n - 1) - 1.0 : 0.0;
    double v = 1.0;
    for (Eigen::Index d = 0; d < m; ++d, v *= t)
      B(i, d) = v;
  }
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(B);
  return qr.householderQ() * Eigen::MatrixXd::Identity(n, m);
}
}  // namespace

Eigen::MatrixXd remove_polynomial(const Eigen::MatrixXd& D, int degree) {
  if (degree + 1 <= 0 || D.rows() == 0 || D.cols() == 0) return D;
  const Eigen::MatrixXd Q = polynomial_basis(D.rows(), degree);
  return D - Q * (Q.transpose() * D);
}

namespace {

double rms_after_polynomial(const Eigen::VectorXd& d, int degree) {
  const Eigen::Index n = d.size();
  if (n <= degree + 1) return 0.0;
  return std::sqrt(remove_polynomial(d, degree).squaredNorm() / static_cast<double>(n));
}

// The base model of Eq. (1) in the reduced space (residual_analysis.hpp: S and γ eliminated per
// position by V₂), with the reference surface sampled at arbitrary points: reading (n, i) sees
// f(x_n + O_i + δ_ni) through the natural cubic spline through f(x_0..x_{N−1}), which is linear
// in those samples, so for given shifts δ the model is still linear in (f, e) and its least-
// squares fit is one dense QR (N = 69: 124 × 68).  δ = 0 is the design of Eqs. (4)–(10).
//
// Gauge: f(x_0) = f(x_{N−1}) = 0 (Eq. 11), f ⟂ the bow t(1 − t) (CurvatureGauge::
// reference_without_curvature, the solver's default) and e_1 = e_4 = 0; f is parametrised in the
// (N − 3)-dimensional subspace that satisfies the three conditions, e by e_2, e_3.  The design
// then has full column rank N − 1 for δ = 0 and stays full rank as δ moves, so the residual is a
// smooth function of the effect parameters (a rank decided by a tolerance would jump when a shift
// makes the bow weakly visible).  This fit is the linearisation point of the effects and the
// source of the residual; the reported separations use the caller's solver options.
class ShiftedBase {
 public:
  explicit ShiftedBase(const FourSensorConfig& cfg) : cfg_(cfg) {
    const int N = cfg.N;
    Eigen::MatrixXd C = Eigen::MatrixXd::Zero(3, N);
    C(0, 0) = 1.0;
    C(1, N - 1) = 1.0;
    C.row(2) = reference_bow(cfg).transpose();
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(C, Eigen::ComputeFullV);
    B_ = svd.matrixV().rightCols(N - 3);
  }

  struct Fit {
    Eigen::VectorXd r;  ///< reduced residual, 2P
    double rss = 0;
    Eigen::MatrixXd Q;  ///< orthonormal basis of the design's column space, 2P × (N − 1)
    Eigen::Matrix<double, 4, 2> V;  ///< the reduction used (complement of span{1, O + δO})
    Eigen::VectorXd f_um, S_um, gamma_rad;
    Eigen::Vector4d e_um = Eigen::Vector4d::Zero();
  };

  /// Least-squares fit of Eq. (1) to readings m (P × 4) with f sampled at x_n + O_i + δ_ni
  /// (δ: P × 4 mm, or empty for none) and γ's lever arms O_i + dO_i.
  Fit fit(const Eigen::MatrixXd& m_um, const Eigen::MatrixXd& shift_mm,
          const Eigen::Vector4d& dO_mm = Eigen::Vector4d::Zero()) const {
    const int N = cfg_.N, P = cfg_.positions(), nf = N - 3;
    const auto k = cfg_.offsets_samples();
    const auto O = cfg_.offsets_mm();
    // Per position S and γ absorb everything in span{1, O + δO}: V spans its complement.
    Eigen::Matrix<double, 4, 2> A;
    for (int i = 0; i < 4; ++i)
      A(i, 0) = 1.0, A(i, 1) = O[static_cast<std::size_t>(i)] + dO_mm(i);
    const Eigen::Matrix4d Qa = Eigen::HouseholderQR<Eigen::Matrix<double, 4, 2>>(A).householderQ();
    const Eigen::Matrix<double, 4, 2> V = Qa.rightCols<2>();
    Eigen::MatrixXd W(4 * P, N);  // f(y_ni) = W.row(4n + i)·f
    for (int n = 0; n < P; ++n)
      for (int i = 0; i < 4; ++i) {
        const std::size_t si = static_cast<std::size_t>(i);
        if (shift_mm.size() == 0)
          W.row(4 * n + i) = Eigen::RowVectorXd::Unit(N, n + k[si]);
        else
          W.row(4 * n + i) = reference_interpolation_weights(
              N, cfg_.dx_mm, n * cfg_.dx_mm + O[si] + shift_mm(n, i), false);
      }
    const Eigen::MatrixXd WB = W * B_;
    Eigen::MatrixXd G(2 * P, nf + 2);
    for (int n = 0; n < P; ++n) {
      G.block(2 * n, 0, 2, nf) = V.transpose() * WB.middleRows(4 * n, 4);
      G.block(2 * n, nf, 2, 2) = V.middleRows(1, 2).transpose();  // e_2, e_3
    }
    Eigen::VectorXd y(2 * P);
    for (int n = 0; n < P; ++n)
      y.segment<2>(2 * n) = V.transpose() * m_um.row(n).transpose();
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(G);
    const Eigen::VectorXd z = qr.solve(y);
    Fit out;
    out.V = V;
    out.r = y - G * z;
    out.rss = out.r.squaredNorm();
    out.Q = qr.householderQ() * Eigen::MatrixXd::Identity(2 * P, nf + 2);
    out.f_um = B_ * z.head(nf);
    out.e_um << 0.0, z(nf), z(nf + 1), 0.0;
    // S and γ per position: least squares of what is left of the four readings on (1, O_i).
    const Eigen::VectorXd fy = W * out.f_um;
    const auto Aqr = A.colPivHouseholderQr();
    out.S_um.resize(P);
    out.gamma_rad.resize(P);
    for (int n = 0; n < P; ++n) {
      Eigen::Vector4d d;
      for (int i = 0; i < 4; ++i)
        d(i) = m_um(n, i) - fy(4 * n + i) - out.e_um(i);
      const Eigen::Vector2d sg = Aqr.solve(d);
      out.S_um(n) = sg(0);
      out.gamma_rad(n) = 1e-3 * sg(1);  // µm/mm → rad
    }
    return out;
  }

  /// Reading-space columns (4P × k) reduced as `fit` reduced the readings.
  static Eigen::MatrixXd reduce(const Fit& fit, const Eigen::MatrixXd& J) {
    const Eigen::Index P = J.rows() / 4;
    Eigen::MatrixXd out(2 * P, J.cols());
    for (Eigen::Index n = 0; n < P; ++n)
      out.middleRows(2 * n, 2) = fit.V.transpose() * J.middleRows(4 * n, 4);
    return out;
  }

  const FourSensorConfig& config() const { return cfg_; }

 private:
  FourSensorConfig cfg_;
  Eigen::MatrixXd B_;  // N × (N − 3), orthonormal basis of the gauge subspace of f
};

EffectContext make_context(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_raw,
                           const Eigen::MatrixXd& t_s, const ShiftedBase::Fit& fit) {
  EffectContext ctx;
  ctx.cfg = cfg;
  ctx.m_um = m_raw;
  ctx.t_s = t_s;
  ctx.f_um = fit.f_um;
  ctx.S_um = fit.S_um;
  ctx.gamma_rad = fit.gamma_rad;
  ctx.e_um = fit.e_um;
  ctx.residual_um.resize(cfg.positions(), 4);
  for (int n = 0; n < cfg.positions(); ++n)
    ctx.residual_um.row(n) = (fit.V * fit.r.segment<2>(2 * n)).transpose();
  ctx.prepare();
  return ctx;
}

// The readings and their times checked (the scan order's times when none were recorded), as
// the context of the raw readings: solve_model fits the rest.  Throws std::invalid_argument.
EffectContext checked_raw_context(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                                  const Eigen::MatrixXd& t_s, const RefineOptions& opts) {
  std::string why;
  if (!cfg.is_valid(&why)) throw std::invalid_argument("invalid configuration: " + why);
  if (!opts.is_valid(&why)) throw std::invalid_argument("invalid refine options: " + why);
  const int P = cfg.positions();
  if (m_um.rows() != P || m_um.cols() != 4)
    throw std::invalid_argument("readings must be P x 4 = " + std::to_string(P) + " x 4, got " +
                                std::to_string(m_um.rows()) + " x " + std::to_string(m_um.cols()));
  if (!m_um.allFinite()) throw std::invalid_argument("readings contain non-finite values");
  EffectContext raw;
  raw.cfg = cfg;
  raw.m_um = m_um;
  raw.t_s = t_s.size() == 0 ? scan_order_times_s(cfg, opts.speed_mm_per_s) : t_s;
  if (raw.t_s.rows() != P || raw.t_s.cols() != 4 || !raw.t_s.allFinite())
    throw std::invalid_argument("reading times must be a finite P x 4 matrix like the readings");
  return raw;
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

// f̂(y + δ) − f̂(y) for every reading, y = x_n + O_i.
Eigen::MatrixXd f_shift_part(const EffectContext& ctx, const Eigen::MatrixXd& shift_mm) {
  const auto O = ctx.cfg.offsets_mm();
  Eigen::MatrixXd d(shift_mm.rows(), 4);
  for (Eigen::Index n = 0; n < shift_mm.rows(); ++n)
    for (int i = 0; i < 4; ++i) {
      const double y = static_cast<double>(n) * ctx.cfg.dx_mm + O[static_cast<std::size_t>(i)];
      d(n, i) = ctx.f_at(y + shift_mm(n, i)) - ctx.f_at(y);
    }
  return d;
}

// The readings split for the exact fit: `rest` = m minus every correction except the shift of
// f's sampling points (f̂(y + δ) − f̂(y) of PE1, PE2, periodic), and the total shift δ.
// The readings split for the exact fit: `rest` = m minus every correction except the shift of
// f's sampling points (f̂(y + δ) − f̂(y) of PE1, PE2, periodic) and the change of γ's lever arm
// (1000·δO_i·γ̂ of PE1); the total shift δ and lever-arm error δO.
struct Split {
  Eigen::MatrixXd rest;
  Eigen::MatrixXd shift_mm;  // empty when no effect shifts f
  Eigen::Vector4d dO_mm = Eigen::Vector4d::Zero();
};

Split split_readings(const Model& M, const EffectContext& ctx) {
  Split s{ctx.m_um, {}, Eigen::Vector4d::Zero()};
  for (std::size_t j = 0; j < M.effects.size(); ++j) {
    Eigen::MatrixXd c = M.effects[j]->correction_um(M.p[j], ctx);
    const Eigen::MatrixXd sh = M.effects[j]->f_shift_mm(M.p[j], ctx.cfg);
    if (sh.size() != 0) {
      c -= f_shift_part(ctx, sh);
      if (s.shift_mm.size() == 0) s.shift_mm = Eigen::MatrixXd::Zero(sh.rows(), 4);
      s.shift_mm += sh;
    }
    const Eigen::Vector4d dO = M.effects[j]->lever_arm_error_mm(M.p[j]);
    if (dO.squaredNorm() > 0) {
      for (Eigen::Index n = 0; n < c.rows(); ++n)
        c.row(n) -= 1000.0 * ctx.gamma_rad(n) * dO.transpose();
      s.dO_mm += dO;
    }
    s.rest -= c;
  }
  return s;
}

// The readings corrected for every effect: Eq. (1) holds for them with f at the nominal points.
// The shifts of all effects are applied together (f̂ at y + Σδ), not one correction per effect.
Eigen::MatrixXd corrected(const Model& M, const EffectContext& ctx) {
  const Split s = split_readings(M, ctx);
  Eigen::MatrixXd m = s.rest;
  if (s.shift_mm.size() != 0) m -= f_shift_part(ctx, s.shift_mm);
  for (Eigen::Index n = 0; n < m.rows(); ++n)
    m.row(n) -= 1000.0 * ctx.gamma_rad(n) * s.dO_mm.transpose();
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
// scaled to unit norm (effects mix units: gains, mm, µm/s): with D the column norms, the scaled
// parameters are p̃ = D·p and the projected, scaled columns (I − H)·J·D⁻¹ = U·Σ·Vᵀ.  The data
// see p only through Vᵀ·D·p: the determined combinations of the parameters are ℓ_j = D·v_j
// (v_j with s_j above tolerance), and the directions no data can see are D⁻¹·v_j of the others
// (absorbed by f, S, γ, e, e.g. a drift common to all configurations).  The estimate is the one
// with no component along those (orthogonal to them in parameter units), which is the span of
// the ℓ_j: so ℓ_jᵀp̂ = v_jᵀp̃̂ is the estimate of ℓ_jᵀp whatever the invisible part of the truth,
// with variance σ²/s_j², and the covariance of p̂ is σ²·(I − ZZᵀ)·D⁻¹VΣ⁻²VᵀD⁻¹·(I − ZZᵀ) (Z the
// invisible directions).  With `p_current` (Gauss–Newton), a direction is kept only when the
// total parameter's signal along it, |c_j + s_j·v_jᵀp̃|, exceeds kappa·σ̂: a direction the data
// barely determine would otherwise put its large uncertainty into the corrected readings and
// from there into S, γ and f; such a direction is set to zero.
struct ProjectedFit {
  Eigen::VectorXd dp;
  Eigen::MatrixXd cov_unit;  // covariance of p̂ / σ², parameter units
  // k × kept, orthonormal (parameter units): the combinations ℓᵀp the data determine; p̂ lies in
  // their span.
  Eigen::MatrixXd determined;
  // k × kept: parameter perturbations whose projected columns span what the fit explains (for the
  // model's column space).
  Eigen::MatrixXd column_directions;
  Eigen::VectorXd relative_sv;
  double delta_rss = 0;
  int identifiable = 0;  // structurally identifiable directions
  int kept = 0;          // directions kept after the significance truncation
};

// Q: orthonormal basis of the model the columns are projected against.
ProjectedFit projected_fit(const Eigen::MatrixXd& Q, const Eigen::MatrixXd& Jr,
                           const Eigen::VectorXd& r, double tol,
                           const Eigen::VectorXd* p_current = nullptr, double kappa = 0.0) {
  ProjectedFit out;
  const Eigen::Index k = Jr.cols();
  out.dp = Eigen::VectorXd::Zero(k);
  out.cov_unit = Eigen::MatrixXd::Zero(k, k);
  out.determined.resize(k, 0);
  out.column_directions.resize(k, 0);
  if (k == 0) return out;
  const int base_dof = static_cast<int>(Q.rows() - Q.cols());
  Eigen::MatrixXd RJ = Jr - Q * (Q.transpose() * Jr);
  Eigen::VectorXd D(k);
  for (Eigen::Index c = 0; c < k; ++c) {
    D(c) = Jr.col(c).norm();
    if (!(D(c) > 0)) D(c) = 1.0;
    RJ.col(c) /= D(c);
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(RJ, Eigen::ComputeThinU | Eigen::ComputeFullV);
  const Eigen::VectorXd& sv = svd.singularValues();
  const Eigen::MatrixXd& V = svd.matrixV();
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
  const int dof = base_dof - kid;
  const double sigma = dof > 0 ? std::sqrt(std::max(0.0, r.squaredNorm() - fit_all) / dof) : 0.0;
  Eigen::VectorXd dps = Eigen::VectorXd::Zero(k);  // scaled step
  Eigen::VectorXd ps = Eigen::VectorXd::Zero(k);
  if (p_current) ps = p_current->cwiseProduct(D);
  std::vector<int> kept, free_dirs;
  for (int j = 0; j < kid; ++j) {
    const Eigen::VectorXd v = V.col(j);
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
    dps -= V.col(j) * V.col(j).dot(ps + dps);
  // Z: the directions no data can see, orthonormal in parameter units.
  const Eigen::Index k0 = k - kid;
  Eigen::MatrixXd Z(k, k0);
  if (k0 > 0) {
    Z = D.cwiseInverse().asDiagonal() * V.rightCols(k0);
    Eigen::HouseholderQR<Eigen::MatrixXd> zq(Z);
    Z = zq.householderQ() * Eigen::MatrixXd::Identity(k, k0);
  }
  // The estimate has no component along Z (see above).
  if (p_current && k0 > 0) {
    Eigen::VectorXd p_new = (ps + dps).cwiseQuotient(D);
    p_new -= Z * (Z.transpose() * p_new);
    dps = p_new.cwiseProduct(D) - ps;
  }
  out.kept = static_cast<int>(kept.size());
  out.dp = dps.cwiseQuotient(D);
  if (out.kept == 0) return out;
  Eigen::MatrixXd Bm(k, out.kept), L(k, out.kept), Cd(k, out.kept);
  for (int q = 0; q < out.kept; ++q) {
    const int j = kept[static_cast<std::size_t>(q)];
    Bm.col(q) = V.col(j).cwiseQuotient(D) / sv(j);  // D⁻¹·v_j / s_j
    L.col(q) = V.col(j).cwiseProduct(D);            // ℓ_j = D·v_j
    Cd.col(q) = V.col(j).cwiseQuotient(D);          // D⁻¹·v_j
  }
  if (k0 > 0) Bm -= Z * (Z.transpose() * Bm);
  out.cov_unit = Bm * Bm.transpose();
  if (out.kept == k) {
    out.determined = Eigen::MatrixXd::Identity(k, k);  // every parameter on its own
  } else {
    Eigen::HouseholderQR<Eigen::MatrixXd> lq(L);
    out.determined = lq.householderQ() * Eigen::MatrixXd::Identity(k, out.kept);
  }
  Eigen::HouseholderQR<Eigen::MatrixXd> cq(Cd);
  out.column_directions = cq.householderQ() * Eigen::MatrixXd::Identity(k, out.kept);
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

// Gauss–Newton on the model's effect parameters with the base unknowns eliminated (variable
// projection): rss(p) = ‖r(p)‖², r(p) the residual of the exact least-squares fit of Eq. (1) to
// the readings corrected with p, f sampled at the points the effects shift it to.  The Jacobian
// is the effects' J projected against that fit's design (Kaufman's approximation of the
// projector's derivative), evaluated at its f̂, Ŝ, γ̂.  A step is accepted only if it lowers
// rss(p) (backtracking, halving up to 10 times); the iteration stops when every
// |Δp_j| < tolerance·u(p_j), when no step lowers rss, or after max_gauss_newton iterations.
Solved solve_model(const ShiftedBase& sb, Model& M, EffectContext ctx, const RefineOptions& opts) {
  const FourSensorConfig& cfg = sb.config();
  const int k = M.total();
  auto evaluate = [&](const Model& model, const EffectContext& c) {
    const Split s = split_readings(model, c);
    return sb.fit(s.rest, s.shift_mm, s.dO_mm);
  };
  auto with_step = [](const Model& from, const Eigen::VectorXd& d) {
    Model to = from;
    Eigen::Index c = 0;
    for (auto& p : to.p) {
      p += d.segment(c, p.size());
      c += p.size();
    }
    return to;
  };
  ShiftedBase::Fit cur = evaluate(M, ctx);
  ctx = make_context(cfg, ctx.m_um, ctx.t_s, cur);
  int it = 0;
  for (; it < (k > 0 ? opts.max_gauss_newton : 0); ++it) {
    cur = evaluate(M, ctx);  // with the rest terms of the current fit
    const Eigen::MatrixXd Jr = ShiftedBase::reduce(cur, model_jacobian(M, ctx));
    const Eigen::VectorXd p_now = concat(M);
    const ProjectedFit fit =
        projected_fit(cur.Q, Jr, cur.r, opts.identifiability_tol, &p_now, opts.direction_threshold);
    const int dof = static_cast<int>(cur.Q.rows() - cur.Q.cols()) - fit.kept;
    const double s2 = dof > 0 ? std::max(0.0, cur.rss - fit.delta_rss) / dof : 0.0;
    double t = 1.0;
    bool accepted = false;
    for (int h = 0; h <= 10; ++h, t *= 0.5) {
      Model trial = with_step(M, t * fit.dp);
      ShiftedBase::Fit tf = evaluate(trial, ctx);
      // (Up to rounding: a move along directions no data see leaves rss unchanged and must be
      // taken, it is what puts the estimate in the span of the determined combinations.)
      if (tf.rss <= cur.rss * (1.0 + 1e-10)) {
        M = std::move(trial);
        cur = std::move(tf);
        accepted = true;
        break;
      }
    }
    if (!accepted) break;  // a minimum of rss up to the linearisation's accuracy
    ctx = make_context(cfg, ctx.m_um, ctx.t_s, cur);
    bool converged = true;
    for (Eigen::Index j = 0; j < k; ++j) {
      const double u = std::sqrt(std::max(0.0, s2 * fit.cov_unit(j, j)));
      const double scale = std::max({u, 1e-9 * std::abs(p_now(j)), 1e-300});
      if (std::abs(t * fit.dp(j)) > opts.gauss_newton_tolerance * scale) converged = false;
    }
    if (converged) {
      ++it;
      break;
    }
  }
  cur = evaluate(M, ctx);
  Solved out{ctx, {}, ResidualSpace(cfg), 0.0, it, {}, {}, 0.0};
  out.m_c = corrected(M, ctx);
  const Eigen::MatrixXd J = model_jacobian(M, ctx);
  const Eigen::VectorXd p_now = concat(M);
  out.last = projected_fit(cur.Q, ShiftedBase::reduce(cur, J), cur.r, opts.identifiability_tol,
                           &p_now, opts.direction_threshold);
  // The model's column space for the residual, its analysis and the next round's scores: the
  // base model and the effects' linearised columns along what the data determine (the corrected
  // readings obey Eq. (1) with the nominal offsets, so the nominal reduction).
  out.space.add(reduce_columns(cfg, J) * out.last.column_directions, opts.identifiability_tol);
  out.rss = out.space.project_out(reduce_readings(cfg, out.m_c)).squaredNorm();
  out.s2 = out.space.dof() > 0 ? out.rss / out.space.dof() : 0.0;
  Eigen::Index c = 0;
  for (const auto& p : M.p) {
    Eigen::VectorXd u(p.size());
    for (Eigen::Index j = 0; j < p.size(); ++j)
      u(j) = std::sqrt(std::max(0.0, out.s2 * out.last.cov_unit(c + j, c + j)));
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
      const ProjectedFit fit = projected_fit(cur.space.basis(), Jr, r, opts.identifiability_tol);
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
        best.score.p_value = f_test_p_value(F, fit.identifiable, dof);
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

// The combinations of effect block [c0, c0 + k) alone that the data determine in the joint model
// (k × d, orthonormal): ℓ (zero outside the block) in the span of the joint determined
// combinations `Dj` (K × kept), i.e. orthogonal to the block rows of their complement.
Eigen::MatrixXd block_determined_directions(const Eigen::MatrixXd& Dj, Eigen::Index c0,
                                            Eigen::Index k) {
  const Eigen::Index K = Dj.rows(), kept = Dj.cols();
  Eigen::MatrixXd comp = Eigen::MatrixXd::Identity(K, K);
  if (kept > 0) {
    Eigen::HouseholderQR<Eigen::MatrixXd> dq(Dj);
    comp = Eigen::MatrixXd(dq.householderQ()).rightCols(K - kept);
  }
  if (comp.cols() == 0) return Eigen::MatrixXd::Identity(k, k);
  Eigen::JacobiSVD<Eigen::MatrixXd> cs(comp.middleRows(c0, k), Eigen::ComputeFullU);
  Eigen::Index rank_c = 0;
  for (Eigen::Index j = 0; j < cs.singularValues().size(); ++j)
    if (cs.singularValues()(j) > 1e-8) ++rank_c;
  return cs.matrixU().rightCols(k - rank_c);
}

// The separation as a linear map of the readings: the caller's estimator at the λ and prior the
// separation `sep` ended with (for a fixed λ the estimate is linear in the readings).
FourSensorOptions linear_options(const FourSensorResult& sep, const FourSensorOptions& base) {
  FourSensorOptions o = base;
  o.compute_uncertainty = false;
  o.iterated_refinements = base.iterated_refinements;
  if (sep.estimator == Estimator::posterior && sep.penalty == Penalty::none) {
    o.rule = LambdaRule::least_squares;
    o.penalty = Penalty::none;
  } else if (sep.rule == LambdaRule::least_squares) {
    o.rule = LambdaRule::least_squares;
  } else {
    o.rule = LambdaRule::fixed;
    o.fixed_lambda = sep.lambda;
    if (sep.estimator == Estimator::posterior) o.penalty = sep.penalty;
  }
  return o;
}

// The reported result for a model: which effects are applied (step_decision.hpp), the separation
// of the readings corrected for them in the gauge of `before`, and the uncertainty they carry.
// A term a step carries into the refined result's uncertainty: G·K·Gᵀ added to the covariance
// of (S, γ, f), G = [G_S; G_γ; G_f] per unit of k parameters (µm, rad, µm), K (k × k) their
// second moment.  Kept apart so that it can be carried again when a later step (the gross-error
// removal, the non-linearity) separates the readings afresh: that separation's σ̂ and covariance
// know nothing of what the steps before it carried.
struct CarriedTerm {
  Eigen::MatrixXd G_S, G_gamma_rad, G_f, K;
  bool empty() const { return K.size() == 0; }
};

// Adds a carried term to a separation's u_S, u_γ, u_f (in quadrature) and to its covariance.
// Returns what it added to u_S², pointwise (P; zeros for an empty term).
Eigen::VectorXd carry(FourSensorResult& r, const CarriedTerm& t) {
  const Eigen::Index P = r.S_um.size();
  if (t.empty()) return Eigen::VectorXd::Zero(P);
  auto var = [&](const Eigen::MatrixXd& G) {
    return Eigen::VectorXd((G * t.K).cwiseProduct(G).rowwise().sum().cwiseMax(0.0));
  };
  const Eigen::VectorXd vS = var(t.G_S);
  auto widen = [](Eigen::VectorXd& u, const Eigen::VectorXd& v) {
    if (u.size() == v.size()) u = (u.array().square() + v.array()).sqrt();
  };
  widen(r.u_S_um, vS);
  widen(r.u_gamma_rad, var(t.G_gamma_rad));
  widen(r.u_f_um, var(t.G_f));
  if (r.covariance) r.covariance->add_low_rank(t.G_S, t.G_gamma_rad, t.G_f, t.K);
  return vS.size() == P ? vS : Eigen::VectorXd::Zero(P);
}

struct Reported {
  FourSensorResult sep;
  Eigen::MatrixXd m_c;  // the readings `sep` separates
  CarriedTerm term;     // what the effects carried into `sep` (applied or not)
  std::vector<StepDecision> decisions;
  std::vector<StepDecision> at_zero;  // the same decisions linearised about zero (linear_at_zero)
  std::vector<bool> applied;
  std::vector<int> undetermined;
  std::vector<double> undetermined_S_um;
  std::vector<std::string> verdicts;
  std::vector<std::string> unbounded;  // RefineResult::unbounded
};

// The readings' own bound on what an effect can be (RefineResult::unbounded,
// RefineOptions::reading_bound).  The sensors read
// m = (f, S, γ, e of Eq. 1) + c + noise, c = J·p the effect's change of the readings: an effect
// whose term in u (its fitted size when declined, its covariance when applied, the part the plan
// cannot determine, what it does to the gauge directions) changes the readings by more than
// reading_bound (3) times what the sensors read at all (RMS about each sensor's mean) would need
// the geometry to cancel two thirds of it at every reading; an undeclared instrument effect does
// not track the geometry, so such a size is not one the data support: the fit left it undetermined
// (it lies along what f, S, γ, e absorb) and only a declared bound can size it.  Measured
// (errsep-refine-sweep --plan single --sigma 0.3 --size 3, seeds 21-40): the runs whose u_S was
// widened x2.4e4 (gain seed 33: pe1 + traverse fitted to a 13 % gain, the traverse's term 5.5e3
// um at the readings of 6.2 um RMS) and x1.3e7 (bump seed 27: a thermal drift of 4.7e4 um among
// four effects fitted to a bump, 8.4e6 um at readings of 8.6 um RMS).  At size 1, seeds 1-40,
// σ 0.05-0.3, 12 effects (1920 runs): the bound holds a term in 23 runs (pe1 4, thermal_all 2,
// traverse 3, bump 14), the largest u_S / raw u_S falls from 1.9e7 to 1.85e3 there (those runs
// say "u_S unbounded"); outside the bump cells (which also got the spike rule, gross_errors.cpp)
// no cell's coverage, S error or worse-beyond-u count changes.  It does not catch a
// term that stays within the readings but that the separation amplifies onto S: u_S up to 23x
// max(S error, raw u_S) without the line (pe1 σ 0.2, seeds 21-40).  RefineOptions::reading_bound,
// default 3.

// The covariance of the model's parameters from the linearisation about zero (the base model of
// the raw readings, every effect absent), with the noise level s2 of the current fit.  For a
// non-linear effect (PE1, PE2, the periodic error: the reference sampled at shifted points) the
// least-squares surface can have minima far from the truth when the effect is weakly determined
// (PE1 on a smooth reference at σ = 0.1 µm: dD4 fitted at 7.9 ± 1.3 mm for a true 0.58 mm, whose
// linear uncertainty about zero is 6.4 mm); the curvature at such a minimum then understates the
// uncertainty, the one about zero does not.
struct LinearAtZero {
  Eigen::VectorXd p;  // the linear least-squares estimate of all parameters about zero
  Eigen::MatrixXd covariance;
};
LinearAtZero linear_at_zero(const ShiftedBase& sb, const Model& M, const EffectContext& base_ctx,
                            const RefineOptions& opts, double s2) {
  Model M0 = M;
  for (auto& p : M0.p)
    p.setZero();
  const ShiftedBase::Fit f0 = sb.fit(base_ctx.m_um, {});
  const Eigen::MatrixXd Jr = ShiftedBase::reduce(f0, model_jacobian(M0, base_ctx));
  const ProjectedFit pf = projected_fit(f0.Q, Jr, f0.r, opts.identifiability_tol);
  return {pf.dp, s2 * pf.cov_unit};
}

// The change of S (µm), γ (µrad) and f (µm) per unit of each column of J (4P × k, J = −∂m_c/∂p):
// the separation at `lin` (linear in the readings) of the readings' change −J (the correction is
// subtracted).  Full: the gauge directions are not removed here.
struct Sensitivities {
  Eigen::MatrixXd S, g, f;
};
Sensitivities sensitivities(const FourSensorConfig& cfg, const Eigen::MatrixXd& J,
                            const FourSensorOptions& lin) {
  const int P = cfg.positions(), N = cfg.N;
  const Eigen::Index K = J.cols();
  Sensitivities out{Eigen::MatrixXd(P, K), Eigen::MatrixXd(P, K), Eigen::MatrixXd(N, K)};
  for (Eigen::Index j = 0; j < K; ++j) {
    Eigen::MatrixXd c(P, 4);
    for (int n = 0; n < P; ++n)
      for (int i = 0; i < 4; ++i)
        c(n, i) = -J(4 * n + i, j);
    const FourSensorResult s = separate_four_sensor(cfg, c, lin);
    out.S.col(j) = s.S_um;
    out.g.col(j) = 1e6 * s.gamma_rad;
    out.f.col(j) = s.f_um;
  }
  return out;
}

// What the linearisation misses of the change the correction of model A (at its parameters)
// makes to S (µm, gauge removed), γ (µrad, gauge removed) and f (µm): the separation at `lin`
// (linear in the readings) of −c(p) + J·p, J = model_jacobian(A, ctx).  Zero for an effect
// linear in its parameters (gain, drift, a traverse); for PE1, PE2 and the periodic error,
// millimetre shifts of where a wavy f is sampled, it can exceed the linear change itself (PE2 at
// σ = 0.2 µm, seed 15 of errsep-refine-sweep: γ changed by 217 µrad rms where the linearisation
// predicts 96).
struct Remainder {
  Eigen::VectorXd S, g, f;
};
Remainder linearisation_remainder(const FourSensorConfig& cfg, const Model& A,
                                  const EffectContext& ctx, const FourSensorOptions& lin) {
  const int P = cfg.positions();
  Remainder out{Eigen::VectorXd::Zero(P), Eigen::VectorXd::Zero(P), Eigen::VectorXd::Zero(cfg.N)};
  if (A.effects.empty()) return out;
  const Eigen::VectorXd Jp = model_jacobian(A, ctx) * concat(A);
  Eigen::MatrixXd r = corrected(A, ctx) - ctx.m_um;
  for (int n = 0; n < P; ++n)
    for (int i = 0; i < 4; ++i)
      r(n, i) += Jp(4 * n + i);
  // An effect linear in its parameters leaves only rounding here: no separation for it.
  const double scale_um = ctx.m_um.cwiseAbs().maxCoeff() + Jp.cwiseAbs().maxCoeff();
  if (r.cwiseAbs().maxCoeff() <= 1e-12 * scale_um) return out;
  const FourSensorResult s = separate_four_sensor(cfg, r, lin);
  out.S = remove_polynomial(s.S_um, 2);
  out.g = 1e6 * remove_polynomial(s.gamma_rad, 1);
  out.f = s.f_um;
  return out;
}

// The declared bound of an effect (RefineOptions::declared), 0 when none.
double declared_bound(const RefineOptions& opts, const std::string& effect) {
  double b = 0.0;
  for (const auto& d : opts.declared)
    if (d.effect == effect) b = std::max(b, d.bound);
  return b;
}

Reported report_model(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_raw, const Model& M,
                      const Solved& cur, const FourSensorResult& before, const RefineOptions& opts,
                      const ShiftedBase& sb, const EffectContext& base_ctx) {
  Reported rep;
  rep.sep = before;
  rep.m_c = m_raw;
  const int P = cfg.positions(), N = cfg.N, K = M.total();
  if (M.effects.empty() || K == 0) return rep;
  // Sensitivities of S (µm), γ (µrad), f (µm) to every parameter: the separation at before's λ
  // of the readings' change −∂c/∂p (the correction is subtracted), with the gauge directions
  // removed: a step keeps before's constant, line and bow of S and constant and line of γ.
  const FourSensorOptions lin = linear_options(before, opts.solve);
  const Sensitivities sens = sensitivities(cfg, model_jacobian(M, cur.ctx), lin);
  Eigen::MatrixXd D_S = sens.S, D_g = sens.g;
  const Eigen::MatrixXd& D_f = sens.f;
  // The part of those changes in the gauge directions (constant, line and bow of S; constant
  // and line of γ): the step keeps the raw separation's, so whatever the effect did to them
  // stays in the result, applied or not (carried into u below).
  const Eigen::MatrixXd D_S_gauge = D_S - remove_polynomial(D_S, 2);
  const Eigen::MatrixXd D_g_gauge = D_g - remove_polynomial(D_g, 1);
  D_S = remove_polynomial(D_S, 2);
  D_g = remove_polynomial(D_g, 1);
  const Eigen::MatrixXd C = cur.s2 * cur.last.cov_unit;
  const LinearAtZero lin0 = linear_at_zero(sb, M, base_ctx, opts, cur.s2);
  const Eigen::VectorXd p = concat(M);
  auto or_ones = [](const Eigen::VectorXd& u, Eigen::Index n) {
    return u.size() == n ? u : Eigen::VectorXd::Ones(n);
  };
  const Eigen::VectorXd uS = or_ones(before.u_S_um, P);
  const Eigen::VectorXd ug = or_ones(1e6 * before.u_gamma_rad, P);
  const Eigen::VectorXd uf = or_ones(before.u_f_um, N);
  // What the model carries into the result: applied parameters their covariance, the others
  // their fitted size, and the part of each effect no combination of this plan determines a
  // scale from the determined part (each undetermined direction as large as the determined ones
  // on average): the data say nothing about it, and a result that ignored it would claim more
  // than the scan can show.
  Eigen::MatrixXd carried = Eigen::MatrixXd::Zero(K, K);
  Eigen::MatrixXd undetermined_part = Eigen::MatrixXd::Zero(K, K);  // the s²·ZZᵀ blocks of it
  // The readings' bound (file comment above report_model): RMS of the raw readings about each
  // sensor's mean, and each effect's change of the readings per unit parameter.
  const Eigen::MatrixXd J_read = model_jacobian(M, cur.ctx);
  const double read_rms_um = std::sqrt((m_raw.rowwise() - m_raw.colwise().mean()).squaredNorm() /
                                       std::max<double>(1, m_raw.size()));
  const double read_bound_um = opts.reading_bound > 0 ? opts.reading_bound * read_rms_um
                                                      : std::numeric_limits<double>::infinity();
  auto at_readings_um = [&](Eigen::Index c, Eigen::Index k, const Eigen::MatrixXd& Km) {
    const Eigen::MatrixXd Je = J_read.middleCols(c, k);
    return std::sqrt(std::max(0.0, (Je * Km).cwiseProduct(Je).sum()) /
                     static_cast<double>(std::max<Eigen::Index>(1, Je.rows())));
  };
  Eigen::VectorXd scale = Eigen::VectorXd::Ones(K);  // per parameter: 1, or the bound's scale
  Model applied;
  Remainder applied_alone;  // the remainder of the one applied effect (reused below)
  Eigen::Index c0 = 0;
  for (std::size_t e = 0; e < M.effects.size(); ++e) {
    const Eigen::Index k = M.p[e].size();
    Model alone;
    alone.effects.push_back(M.effects[e]);
    alone.p.push_back(M.p[e]);
    const Remainder rem = linearisation_remainder(cfg, alone, cur.ctx, lin);
    const std::vector<QuantityImpact> q = {{"S", "um", D_S.middleCols(c0, k), uS, rem.S},
                                           {"gamma", "urad", D_g.middleCols(c0, k), ug, rem.g},
                                           {"f", "um", D_f.middleCols(c0, k), uf, rem.f}};
    const Eigen::VectorXd pe = p.segment(c0, k);
    const Eigen::MatrixXd Ce = C.block(c0, c0, k, k);
    StepDecision d = decide_step(pe, Ce, q, opts.decision);
    // The same decision with the uncertainty of the linearisation about zero: a correction is
    // applied only when both say so (see covariance_at_zero).
    // (On B itself: the lower bound is taken once, on the fitted parameters.)
    StepDecisionOptions at_zero = opts.decision;
    at_zero.bias_z = 0.0;
    StepDecision d0 =
        decide_step(lin0.p.segment(c0, k), lin0.covariance.block(c0, c0, k, k), q, at_zero);
    if (d.apply) {
      if (!d0.apply) {
        d.apply = false;
        d.reason = "not determined well enough about zero, where the fit is linear: " + d0.reason;
      }
    }
    // The part of the effect this plan cannot determine (see `carried` above): when it reaches
    // S beyond a tenth of u_S the effect is reported not identifiable from this plan and, unless
    // RefineOptions::apply_unidentifiable, not applied: its determined part alone can make S
    // worse where the two parts partly cancel (thermal drift on one configuration, single plan:
    // S 0.64 -> 2.16 um with u_S 0.95).
    const Eigen::MatrixXd W = block_determined_directions(cur.last.determined, c0, k);
    const Eigen::Index k0 = k - W.cols();
    double und = 0.0, s2_und = 0.0;
    Eigen::MatrixXd Z;
    if (k0 > 0) {
      Z = Eigen::MatrixXd::Identity(k, k);
      if (W.cols() > 0) {
        Eigen::HouseholderQR<Eigen::MatrixXd> wq(W);
        Z = Eigen::MatrixXd(wq.householderQ()).rightCols(k0);
      }
      s2_und = pe.squaredNorm() / static_cast<double>(std::max<Eigen::Index>(1, W.cols()));
      und = std::sqrt(s2_und * (D_S.middleCols(c0, k) * Z).squaredNorm() / P);
      // A declared bound sizes what the data cannot (Type B, rectangular: bound²/3 per
      // combination) when it says more than the guess from the determined part; the verdict's
      // "not identifiable" stays the data's (und above).
      const double b = declared_bound(opts, M.effects[e]->name());
      s2_und = std::max(s2_und, b * b / 3.0);
    }
    const bool unidentifiable = k0 > 0 && und > 0.1 * d.quantity("S")->rms_u_base;
    if (d.apply && unidentifiable && !opts.apply_unidentifiable) {
      d.apply = false;
      d.reason = "not identifiable from this plan, so not applied (" + d.reason + ")";
    }
    if (d.apply && opts.apply_requires_identifiable) {
      RefineOptions o = opts;
      o.apply_requires_identifiable = false;  // effect_identifiability reports a model too
      const EffectIdentifiability id =
          effect_identifiability(cfg, m_raw, base_ctx.t_s, *M.effects[e], o);
      if (!id.identifiable) {
        d.apply = false;
        d.reason = "not applied, the plan does not let it halve the error (" + id.brief() + "; " +
                   d.reason + ")";
      }
    }
    // What the effect would carry into u, at the readings: the larger of its own term (applied:
    // covariance; declined: fitted size; plus the undetermined part) and its gauge-direction term
    // (fitted size, covariance and undetermined part).  Beyond the readings' bound the data do
    // not determine it (RefineOptions::reading_bound): a correction whose own scatter is that large
    // is not applied, and the term is held at the bound with the result saying u_S is unbounded.
    const Eigen::MatrixXd K_und =
        k0 > 0 ? Eigen::MatrixXd(s2_und * Z * Z.transpose()) : Eigen::MatrixXd::Zero(k, k);
    const Eigen::MatrixXd K_gauge = pe * pe.transpose() + Ce + K_und;
    auto term_at_readings = [&](bool apply) {
      return std::max(
          at_readings_um(c0, k, (apply ? Ce : Eigen::MatrixXd(pe * pe.transpose())) + K_und),
          at_readings_um(c0, k, K_gauge));
    };
    double read_um = term_at_readings(d.apply);
    const bool has_declared = declared_bound(opts, M.effects[e]->name()) > 0;
    if (read_um > read_bound_um && d.apply) {
      d.apply = false;
      char buf[260];
      std::snprintf(buf, sizeof buf,
                    "not determined by the data: its term would change the readings by %.3g um "
                    "rms, more than %.3g x their own %.3g um rms (%s)",
                    read_um, opts.reading_bound, read_rms_um, d.reason.c_str());
      d.reason = buf;
      read_um = term_at_readings(false);
    }
    bool unbounded_here = false;
    if (read_um > read_bound_um) {
      scale.segment(c0, k).setConstant(read_bound_um / read_um);
      unbounded_here = !has_declared;
    }
    if (d.apply) {
      carried.block(c0, c0, k, k) = Ce;
      applied.effects.push_back(M.effects[e]);
      applied.p.push_back(M.p[e]);
      applied_alone = rem;
    } else {
      carried.block(c0, c0, k, k) = pe * pe.transpose();
    }
    if (k0 > 0) {
      carried.block(c0, c0, k, k) += K_und;
      undetermined_part.block(c0, c0, k, k) = K_und;
    }
    rep.undetermined.push_back(static_cast<int>(k0));
    rep.undetermined_S_um.push_back(und);
    std::string v =
        describe_decision(M.effects[e]->name(), M.effects[e]->parameter_names(), pe, cur.u[e], d);
    // Where the linearisation the decision and u rest on misses more than a tenth of u_S over
    // the step, the user is told by how much (it is in V, and in u when applied).
    const double rem_S_um = std::sqrt(rem.S.squaredNorm() / P);
    if (rem_S_um > 0.1 * d.quantity("S")->rms_u_base) {
      char buf[300];
      std::snprintf(buf, sizeof buf,
                    "; not linear in its parameters over the step: the correction changes S by "
                    "%.3g um rms, gamma by %.3g urad rms beyond its linearisation (counted in V)",
                    rem_S_um, std::sqrt(rem.g.squaredNorm() / P));
      v += buf;
    }
    if (unidentifiable) {
      char buf[300];
      std::snprintf(buf, sizeof buf,
                    "; not identifiable from this plan: %d of %d parameter combinations are not "
                    "determined by this scan and could change S by %.3g um rms (added to u_S: "
                    "a closing pass or reversed traverses determine them)",
                    static_cast<int>(k0), static_cast<int>(k), und);
      v += buf;
    }
    if (read_um > read_bound_um) {
      char buf[300];
      std::snprintf(buf, sizeof buf,
                    "its term in u would change the readings by %.3g um rms, more than %.3g x "
                    "their own %.3g um rms: the data do not bound it, u carries it at that bound",
                    read_um, opts.reading_bound, read_rms_um);
      if (unbounded_here) {
        rep.unbounded.push_back("u_S unbounded: " + M.effects[e]->name() +
                                " not determined by this plan; declare a bound (" + buf + ")");
        v += "; " + rep.unbounded.back();
      } else {
        v +=
            std::string("; held at the readings' bound although a bound is declared (") + buf + ")";
      }
    }
    rep.verdicts.push_back(std::move(v));
    rep.applied.push_back(d.apply);
    rep.decisions.push_back(std::move(d));
    rep.at_zero.push_back(std::move(d0));
    c0 += k;
  }
  // The separation of the readings corrected for the applied effects (a fresh one even when
  // none is applied: its covariance object is extended below and `before`'s must stay as it is).
  if (!applied.effects.empty()) rep.m_c = corrected(applied, cur.ctx);
  FourSensorResult after = separate_four_sensor(cfg, rep.m_c, opts.solve);
  after.S_um = before.S_um + remove_polynomial(after.S_um - before.S_um, 2);
  after.gamma_rad = before.gamma_rad + remove_polynomial(after.gamma_rad - before.gamma_rad, 1);
  // What the effects did to the gauge directions of the raw separation stays in the result
  // (the step keeps them): its size is estimated by the fitted one, conservatively by its
  // variance on top (E[p̂p̂ᵀ] = ppᵀ + C), and the undetermined part as above.  Without it the
  // pointwise u_S did not cover where an effect was applied and halved the shape error (periodic
  // error at σ = 0.05 µm: 0.45 of the points within 2 u_S, the shape 0.96): the effect had moved
  // the raw separation's bow.
  //
  // The terms above map the parameters' second moment onto S, γ, f through the sensitivities at
  // the fit, i.e. the correction linearised there; what that misses over the step of the applied
  // corrections (linearisation_remainder: PE1, PE2, the periodic error) is carried as one more
  // term (Type B, in quadrature), as the decision counted it in V.  Before it was (PE2 at
  // σ = 0.2 µm, seed 15): γ 30 -> 224 µrad with u_γ 134.
  // With one effect applied (the usual case) it is that effect's own remainder, computed for its
  // decision above; the remainders of two applied effects do not add, so theirs is computed
  // jointly.
  const Remainder nl = applied.effects.size() == 1
                           ? std::move(applied_alone)
                           : linearisation_remainder(cfg, applied, cur.ctx, lin);
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(2 * K + 1, 2 * K + 1);
  // Each effect's rows and columns scaled to the readings' bound where it applies (a congruence:
  // the second moment stays positive semi-definite).
  G.topLeftCorner(K, K) = scale.asDiagonal() * carried * scale.asDiagonal();
  G.block(K, K, K, K) =
      scale.asDiagonal() * (p * p.transpose() + C + undetermined_part) * scale.asDiagonal();
  G(2 * K, 2 * K) = 1.0;
  Eigen::MatrixXd GS(P, 2 * K + 1), Gg(P, 2 * K + 1), Gf = Eigen::MatrixXd::Zero(N, 2 * K + 1);
  GS << D_S, D_S_gauge, nl.S;
  Gg << D_g, D_g_gauge, nl.g;
  Gf.leftCols(K) = D_f;
  Gf.col(2 * K) = nl.f;
  rep.term = CarriedTerm{GS, 1e-6 * Gg, Gf, G};
  carry(after, rep.term);
  rep.sep = std::move(after);
  return rep;
}

// The declared bounds of effects not in the final model (RefineOptions::declared): a Type B term.
// With the rectangular prior p ~ (0, b²/3·I) and the final model's residual r (reduced, its
// columns projected out, noise s²), the posterior of the effect's parameters is
//   C = (JᵣᵀJᵣ/s² + 3/b²·I)⁻¹,  μ = C·Jᵣᵀr/s²
// (Jᵣ the effect's reduced columns without what the model already spans): what the data
// determine is bounded by them, the rest by the bound alone.  Nothing of it is corrected, so its
// whole expected square E[ppᵀ | data] = C + μμᵀ reaches S, γ and f through their full
// sensitivities (the gauge directions too: the refined result keeps the raw separation's).  An
// effect with a structural choice (thermal τ, a period) is averaged over its variants (the
// choice uniform over the effect's own grid).  Returns the sensitivities and that second moment,
// stacked over the effects and variants, for u and the covariance.
struct DeclaredTerm {
  Eigen::MatrixXd GS, Gg, Gf, K;
  std::vector<std::string> notes;
};
DeclaredTerm declared_term(const FourSensorConfig& cfg, const Model& M, const Solved& cur,
                           const FourSensorResult& before, const RefineOptions& opts,
                           const std::vector<std::unique_ptr<ModelEffect>>& library) {
  DeclaredTerm out;
  const int P = cfg.positions(), N = cfg.N;
  std::vector<Eigen::MatrixXd> S, g, f, G;
  const FourSensorOptions lin = linear_options(before, opts.solve);
  const Eigen::VectorXd r = cur.space.project_out(reduce_readings(cfg, cur.m_c));
  const double s2 = std::max(cur.s2, 1e-300);
  for (const auto& d : opts.declared) {
    const bool in_model = std::any_of(M.effects.begin(), M.effects.end(),
                                      [&](const auto& e) { return e->name() == d.effect; });
    if (in_model) {
      char buf[200];
      std::snprintf(buf, sizeof buf,
                    "%s declared within +-%.3g per parameter (Type B): in the model, it sizes "
                    "the combinations this plan cannot determine",
                    d.effect.c_str(), d.bound);
      out.notes.push_back(buf);
      continue;
    }
    const ModelEffect* proto = nullptr;
    for (const auto& e : library)
      if (e->name() == d.effect) proto = e.get();
    if (!proto) {
      out.notes.push_back(d.effect + " declared, but not in the library used: not carried");
      continue;
    }
    const auto variants = proto->variants(cur.ctx);
    const double w = 1.0 / static_cast<double>(std::max<std::size_t>(1, variants.size()));
    double var_S = 0.0;
    for (const auto& v : variants) {
      const Eigen::Index k = v->parameter_count();
      const Eigen::MatrixXd J = v->jacobian(Eigen::VectorXd::Zero(k), cur.ctx);
      const Eigen::MatrixXd Jr = cur.space.project_out(reduce_columns(cfg, J));
      Eigen::MatrixXd A = Jr.transpose() * Jr / s2;
      A.diagonal().array() += 3.0 / (d.bound * d.bound);
      const Eigen::LDLT<Eigen::MatrixXd> ldlt(A);
      const Eigen::MatrixXd C = ldlt.solve(Eigen::MatrixXd::Identity(k, k));
      const Eigen::VectorXd mu = C * (Jr.transpose() * r) / s2;
      const Sensitivities sv = sensitivities(cfg, J, lin);
      S.push_back(sv.S);
      g.push_back(sv.g);
      f.push_back(sv.f);
      G.push_back(w * (C + mu * mu.transpose()));
      var_S += ((sv.S * G.back()).cwiseProduct(sv.S)).sum() / P;
    }
    char buf[300];
    std::snprintf(buf, sizeof buf,
                  "%s declared within +-%.3g per parameter (Type B, rectangular; not in the "
                  "model): adds %.3g um rms to u_S for what this plan cannot rule out",
                  d.effect.c_str(), d.bound, std::sqrt(std::max(0.0, var_S)));
    out.notes.push_back(buf);
  }
  Eigen::Index K = 0;
  for (const auto& s : S)
    K += s.cols();
  out.GS.resize(P, K);
  out.Gg.resize(P, K);
  out.Gf.resize(N, K);
  out.K = Eigen::MatrixXd::Zero(K, K);
  Eigen::Index c = 0;
  for (std::size_t j = 0; j < S.size(); ++j) {
    const Eigen::Index k = S[j].cols();
    out.GS.middleCols(c, k) = S[j];
    out.Gg.middleCols(c, k) = g[j];
    out.Gf.middleCols(c, k) = f[j];
    out.K.block(c, c, k, k) = G[j];
    c += k;
  }
  return out;
}

// The gauge floor.  The refined S and γ keep the raw separation's constant, line and bow of S
// and constant and line of γ (report_model: a step never moves what the data cannot see), so
// their error in those directions is the raw separation's error there, whatever the later
// separations' σ̂: when a correction lowers the residual (an applied effect, a removed spike, a
// corrected non-linearity), the fresh separation's σ̂ falls and its covariance, gauge directions
// included, with it, but the gauge directions of the result did not get the correction.  So the
// refined covariance of those five functionals, q = [Q_Sᵀ S (µm); Q_γᵀ γ (µrad)] with Q_S, Q_γ
// orthonormal bases of the polynomials remove_polynomial removes, must be at least the raw
// separation's: what it lacks, the positive part of K_raw − K_refined, is added.  When nothing
// was corrected the refined covariance already holds the raw one (it is the raw separation plus
// the declined effects' terms) and the floor adds nothing.  Measured (errsep-refine-sweep --plan
// single, seeds 1-20 / 21-40): effect bump, seed 14, σ 0.05: three readings of the bump removed as
// spikes, u_S 1.38 -> 0.54 um rms without the floor, 1.21 with it (raw 1.38; the shape's share
// stays at the lower σ̂); no cell's coverage of u_S fell; pe1 at 0.05 rose 0.985 -> 0.998 and
// 0.946 -> 0.998 (over 0.99: the raw σ̂ the gauge keeps holds PE1's misfit).
CarriedTerm gauge_floor(const FourSensorConfig& cfg, const FourSensorResult& raw,
                        const FourSensorResult& refined) {
  const int P = cfg.positions(), N = cfg.N;
  const Eigen::MatrixXd QS = polynomial_basis(P, 2), Qg = polynomial_basis(P, 1);
  const Eigen::Index kS = QS.cols(), k = kS + Qg.cols();
  // Functional j: a_j·S + b_j·γ (γ in rad, so b in 1e6 per rad for µrad).
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(P, k), B = Eigen::MatrixXd::Zero(P, k);
  A.leftCols(kS) = QS;
  B.rightCols(k - kS) = 1e6 * Qg;
  auto functionals = [&](FourSensorCovariance& c) {
    Eigen::MatrixXd K(k, k);
    Eigen::VectorXd v(k);
    for (Eigen::Index i = 0; i < k; ++i)
      v(i) = c.variance(A.col(i), B.col(i), {});
    for (Eigen::Index i = 0; i < k; ++i) {
      K(i, i) = v(i);
      for (Eigen::Index j = i + 1; j < k; ++j)
        K(i, j) = K(j, i) =
            0.5 * (c.variance(A.col(i) + A.col(j), B.col(i) + B.col(j), {}) - v(i) - v(j));
    }
    return K;
  };
  const Eigen::MatrixXd Kr = functionals(*raw.covariance), Ka = functionals(*refined.covariance);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Kr - Ka);
  // Negative eigenvalues (the refined result already holds more there) and rounding are dropped.
  const double tiny = 1e-9 * std::max(Kr.trace(), 1e-300);
  Eigen::VectorXd ev = es.eigenvalues();
  for (Eigen::Index i = 0; i < ev.size(); ++i)
    if (!(ev(i) > tiny)) ev(i) = 0.0;
  CarriedTerm t;
  t.K = es.eigenvectors() * ev.asDiagonal() * es.eigenvectors().transpose();
  t.G_S = Eigen::MatrixXd::Zero(P, k);
  t.G_S.leftCols(kS) = QS;
  t.G_gamma_rad = Eigen::MatrixXd::Zero(P, k);
  t.G_gamma_rad.rightCols(k - kS) = 1e-6 * Qg;
  t.G_f = Eigen::MatrixXd::Zero(N, k);
  if (ev.maxCoeff() <= 0.0) t.K.resize(0, 0);
  return t;
}

}  // namespace

ProfileErrors profile_errors(const FourSensorResult& r, const RefineTruth& truth) {
  ProfileErrors e;
  if (truth.S_um.size() == r.S_um.size()) e.S_um = rms_after_polynomial(r.S_um - truth.S_um, 2);
  if (truth.gamma_rad.size() == r.gamma_rad.size())
    e.gamma_urad = 1e6 * rms_after_polynomial(r.gamma_rad - truth.gamma_rad, 1);
  if (truth.f_um.size() == r.f_um.size()) e.f_um = rms_after_polynomial(r.f_um - truth.f_um, 2);
  return e;
}

FourSensorOptions linearised_options(const FourSensorResult& sep, const FourSensorOptions& base) {
  return linear_options(sep, base);
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
  for (const auto& f : trace.findings)
    out += "; " + f;
  for (const auto& f : gross.findings)
    out += "; " + f + (gross_removed ? "" : " (not removed: RefineOptions::remove_gross_errors)");
  if (nonlinearity.detected) out += "; " + nonlinearity.finding;
  for (const auto& u : unbounded)
    out += "; " + u;
  if (!model_complete()) out += "; model incomplete";
  return out;
}

EffectFit fit_effects(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                      const Eigen::MatrixXd& t_s_in,
                      const std::vector<std::shared_ptr<const ModelEffect>>& effects,
                      const std::vector<Eigen::VectorXd>& start, const RefineOptions& opts) {
  const EffectContext raw = checked_raw_context(cfg, m_um, t_s_in, opts);
  if (!start.empty() && start.size() != effects.size())
    throw std::invalid_argument("fit_effects: one start vector per effect");
  const ShiftedBase sb(cfg);
  Model M;
  for (std::size_t j = 0; j < effects.size(); ++j) {
    M.effects.push_back(effects[j]);
    const Eigen::VectorXd p0 =
        start.empty() ? Eigen::VectorXd::Zero(effects[j]->parameter_count()) : start[j];
    if (p0.size() != effects[j]->parameter_count())
      throw std::invalid_argument("fit_effects: start vector of the wrong size");
    M.p.push_back(p0);
  }
  Model M0;
  const Solved base = solve_model(sb, M0, raw, opts);
  const Solved s = solve_model(sb, M, base.ctx, opts);
  EffectFit out;
  out.parameters = M.p;
  out.u_parameters = s.u;
  out.covariance = s.s2 * s.last.cov_unit;
  out.determined = s.last.determined;
  out.rss_um2 = s.rss;
  out.dof = s.space.dof();
  out.sigma_um = std::sqrt(s.s2);
  out.iterations = s.iterations;
  out.m_corrected_um = s.m_c;
  return out;
}

std::string EffectIdentifiability::brief() const {
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "%s: %s from this plan (%d of %d combinations determined, the rest could move S "
                "by %.3g um; predicted S error %.3g -> %.3g um, gamma %.3g -> %.3g urad with the "
                "correction)",
                effect.c_str(), identifiable ? "identifiable" : "NOT identifiable", determined,
                parameters, undetermined_S_um, predicted_S_before_um, predicted_S_after_um,
                predicted_gamma_before_urad, predicted_gamma_after_urad);
  return buf;
}

EffectIdentifiability effect_identifiability(const FourSensorConfig& cfg,
                                             const Eigen::MatrixXd& m_um,
                                             const Eigen::MatrixXd& t_s_in,
                                             const ModelEffect& effect, const RefineOptions& opts) {
  const EffectContext raw = checked_raw_context(cfg, m_um, t_s_in, opts);
  const int P = cfg.positions();
  EffectIdentifiability out;
  out.effect = effect.name();
  out.description = effect.description();
  out.parameters = effect.parameter_count();
  const ShiftedBase sb(cfg);
  Model M;
  const Solved base = solve_model(sb, M, raw, opts);
  std::vector<std::unique_ptr<ModelEffect>> one;
  one.push_back(effect.clone());
  const std::vector<Scored> scored = score_candidates(cfg, base, one, M, opts, {});
  if (scored.empty() || !scored.front().variant) return out;  // no direction the data see
  out.description = scored.front().variant->description();
  M.effects.push_back(scored.front().variant);
  M.p.push_back(scored.front().p0);
  const Solved cur = solve_model(sb, M, base.ctx, opts);
  const FourSensorResult before = separate_four_sensor(cfg, m_um, opts.solve);
  const Reported rep = report_model(cfg, m_um, M, cur, before, opts, sb, base.ctx);
  out.determined = out.parameters - rep.undetermined.front();
  out.undetermined_S_um = rep.undetermined_S_um.front();
  // The separation's own error of the shape (S without its constant, line and bow, γ without
  // its constant and line: what a step can change, the sensitivities have the gauge removed
  // too): the pointwise u includes the gauge directions' uncertainty, which no step touches.
  const StepDecision& d = rep.decisions.front();
  out.u_S_um = d.quantity("S")->rms_u_base;
  out.u_gamma_urad = d.quantity("gamma")->rms_u_base;
  if (before.covariance) {
    std::vector<int> all(static_cast<std::size_t>(P));
    for (int n = 0; n < P; ++n)
      all[static_cast<std::size_t>(n)] = n;
    const Eigen::MatrixXd VS = before.covariance->covariance_S(all);
    const Eigen::MatrixXd VSs = remove_polynomial(remove_polynomial(VS, 2).transpose(), 2);
    out.u_S_um = std::sqrt(std::max(0.0, VSs.trace()) / P);
    const Eigen::MatrixXd Bg = remove_polynomial(Eigen::MatrixXd::Identity(P, P), 1);
    double vg = 0.0;
    for (int n = 0; n < P; ++n)
      vg += before.covariance->variance({}, Bg.col(n), {});
    out.u_gamma_urad = 1e6 * std::sqrt(std::max(0.0, vg) / P);
  }
  // The raw separation's σ̂ contains the effect's misfit (PE1 at σ = 0.05 µm: 0.10 µm): the noise
  // the answer has once the effect is modelled is the σ̂ of the fit with it.
  if (before.sigma_um > 0 && cur.s2 > 0) {
    const double scale = std::min(1.0, std::sqrt(cur.s2) / before.sigma_um);
    out.u_S_um *= scale;
    out.u_gamma_urad *= scale;
  }
  // Predicted errors from one decision's figures: the bias at its lower confidence bound (the
  // same B − z·sd(B) the decision uses, shared out over the quantities in proportion), so that
  // a fit chosen for its own size does not predict a gain it cannot deliver.
  auto hyp = [](double a, double b) { return std::sqrt(a * a + b * b); };
  struct Predicted {
    double S_before, S_after, g_before, g_after;
  };
  auto predict = [&](const StepDecision& x) {
    const double f = x.bias_sum > 0 ? std::max(0.0, x.bias_bound / x.bias_sum) : 0.0;
    const QuantityEffect* S = x.quantity("S");
    const QuantityEffect* g = x.quantity("gamma");
    return Predicted{hyp(out.u_S_um, std::sqrt(f) * S->rms_bias),
                     hyp(hyp(out.u_S_um, S->rms_added_u), out.undetermined_S_um),
                     hyp(out.u_gamma_urad, std::sqrt(f) * g->rms_bias),
                     hyp(out.u_gamma_urad, g->rms_added_u)};
  };
  auto halves = [](const Predicted& x) {
    return x.S_after <= 0.5 * x.S_before && x.g_after <= 0.5 * x.g_before;
  };
  // The fitted point's linearisation and the one about zero (as the refine decides: both).
  const Predicted a = predict(d), z = predict(rep.at_zero.front());
  const Predicted& w = halves(a) && !halves(z) ? z : a;  // the one that says no, if one does
  out.predicted_S_before_um = w.S_before;
  out.predicted_S_after_um = w.S_after;
  out.predicted_gamma_before_urad = w.g_before;
  out.predicted_gamma_after_urad = w.g_after;
  out.from_plan = out.undetermined_S_um <= 0.1 * out.u_S_um;
  out.identifiable = out.from_plan && halves(a) && halves(z);
  return out;
}

RefineResult refine_four_sensor(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                                const Eigen::MatrixXd& t_s_in, const RefineOptions& opts,
                                const RefineTruth* truth,
                                std::vector<std::unique_ptr<ModelEffect>> library) {
  const EffectContext raw = checked_raw_context(cfg, m_um, t_s_in, opts);
  const int P = cfg.positions();
  const Eigen::MatrixXd t_s = raw.t_s;
  if (library.empty()) library = default_effect_library();

  RefineResult res;
  res.t_s = t_s;
  res.model_name = "zhao2019-eq1";
  res.alpha_per_candidate = opts.alpha / static_cast<double>(library.size());
  res.alpha_residual = opts.residual.alpha;

  const ShiftedBase sb(cfg);
  Model M;
  Solved cur = solve_model(sb, M, raw, opts);
  const EffectContext base_ctx = cur.ctx;  // the base model fitted to the raw readings
  res.before = separate_four_sensor(cfg, m_um, opts.solve);
  Reported current;
  current.sep = res.before;
  current.m_c = m_um;
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
  //
  // The verdict allows for the estimate's uncertainty: an effect is implausible if its
  // parameters are out of range even when each is moved 2 u toward zero (the data demand an
  // out-of-range value), or if the estimate itself is beyond three times the range whatever its
  // uncertainty (the correction is applied at the estimate, and one that far out does more harm
  // than the effect it would stand for: a gain of 2.4 ± 1.2 fitted to a bump).  At σ = 0.2 µm a
  // true 5 % gain of configuration 3 is fitted as g4 = 0.21 ± 0.11 (configuration 4's gain is
  // poorly determined); judged on the estimate alone it was rejected, and PE1 plus a 0.5 µm/s
  // drift stood in for it (S error 1.5 -> 91 µm).
  struct Snapshot {
    Model M;
    Solved cur;
    std::size_t steps = 0;
    Reported reported;
    ResidualAnalysis residual;
    std::string model_name;
  };
  auto implausibility_of = [&](const Model& model, const Solved& s, std::size_t e) {
    const Eigen::VectorXd& p = model.p[e];
    const Eigen::VectorXd& u = s.u[e];
    Eigen::VectorXd q(p.size());
    for (Eigen::Index j = 0; j < p.size(); ++j)
      q(j) = std::copysign(std::max(0.0, std::abs(p(j)) - 2.0 * u(j)), p(j));
    std::string reason = model.effects[e]->implausibility(q, s.ctx);
    if (!reason.empty()) return reason + " with every parameter moved 2 u toward zero";
    reason = model.effects[e]->implausibility(p / 3.0, s.ctx);
    if (!reason.empty()) return reason + " at a third of the estimate (beyond 3x the range)";
    return reason;
  };
  Snapshot plausible{M, cur, res.steps.size(), current, res.residual, res.model_name};
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
      Solved next = solve_model(sb, M, cur.ctx, opts);
      if (M.effects.size() >= 2) {
        // A second start for the joint re-solve: every effect from zero, linearised at the base
        // model of the raw readings.  An effect added alone may have absorbed the signature of
        // one still missing (PE1 fitted alone to PE1 plus a periodic positioning error: dD4 of
        // 8 mm instead of 0.6); continuing from there can end in a local minimum of the joint
        // problem that the joint linearisation at zero does not share.  The better end counts.
        Model M0 = M;
        for (auto& p : M0.p)
          p.setZero();
        Solved alt = solve_model(sb, M0, base_ctx, opts);
        if (alt.rss < next.rss) {
          M = std::move(M0);
          next = std::move(alt);
        }
      }
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
      st.description = M.effects.back()->description(st.parameters);
      st.u_parameters = cur.u.back();
      {
        // The added effect's block of the joint linearisation, and the combinations ℓᵀp of its
        // parameters alone that the data determine.
        const Eigen::Index k = st.parameters.size(), c0 = M.total() - k;
        st.covariance = cur.s2 * cur.last.cov_unit.block(c0, c0, k, k);
        st.identifiable_directions = block_determined_directions(cur.last.determined, c0, k);
        st.identifiable = static_cast<int>(st.identifiable_directions.cols());
      }
      st.rss_after_um2 = cur.rss;
      st.rms_after_um = std::sqrt(cur.rss / (4.0 * P));
      const ResidualAnalysis ra = analyse(cur);
      st.dof_after = ra.dof;
      st.sigma_after_um = ra.sigma_um;
      st.whiteness_after = ra.whiteness;
      st.dominant_period_mm = ra.dominant_period_mm;
      // What the user gets: the effects whose correction makes S, γ, f better applied, the
      // others carried in the uncertainty (step_decision.hpp), the gauge of the raw separation.
      Reported rep = report_model(cfg, m_um, M, cur, res.before, opts, sb, base_ctx);
      st.applied = rep.applied.back();
      st.decision = rep.decisions.back();
      st.undetermined = rep.undetermined.back();
      st.undetermined_S_um = rep.undetermined_S_um.back();
      st.verdict = rep.verdicts.back();
      if (truth) {
        st.error_before = profile_errors(current.sep, *truth);
        st.error_after = profile_errors(rep.sep, *truth);
      }
      current = std::move(rep);
      res.residual = ra;
      res.model_name += "+" + st.effect;
      res.steps.push_back(std::move(st));
      bool all_plausible = true;
      for (std::size_t e = 0; e < M.effects.size(); ++e)
        all_plausible = all_plausible && implausibility_of(M, cur, e).empty();
      if (all_plausible)
        plausible = Snapshot{M, cur, res.steps.size(), current, res.residual, res.model_name};
    }
    // The verdict on the joint model's parameters.
    std::vector<std::size_t> bad;
    for (std::size_t e = 0; e < M.effects.size(); ++e)
      if (!implausibility_of(M, cur, e).empty()) bad.push_back(e);
    if (bad.empty()) break;
    if (res.stop_reason == "maximum number of effects reached") {
      // The caller capped the model below what the data need: the effects in it stand in for the
      // missing ones.  They stay (the caller asked for this many), flagged, and the verdict is
      // "incomplete".
      for (std::size_t e : bad)
        res.implausible_kept.push_back(M.effects[e]->name() + ": implausible parameters (" +
                                       implausibility_of(M, cur, e) +
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
      rc.reason = "rejected: implausible parameters (" + implausibility_of(M, cur, e) + ")";
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
    current = plausible.reported;
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
  res.covariance = cur.s2 * cur.last.cov_unit;
  res.determined = cur.last.determined;
  if (!M.effects.empty() && current.decisions.size() != M.effects.size())
    current = report_model(cfg, m_um, M, cur, res.before, opts, sb, base_ctx);
  res.decisions = current.decisions;
  res.applied = current.applied;
  res.verdicts = current.verdicts;
  res.unbounded = current.unbounded;
  res.m_corrected_um = current.m_c;
  res.after = M.effects.empty() ? res.before : current.sep;
  // Additive analyses of the final residual (issue 16 item 3): the trace is reported only; a
  // spike or step found is taken out of the separation, never absorbed into S.
  // The gross errors first: the trace is of the model with them in it (a spike left in the
  // residual would show as a dependence on whatever variable its reading happens to extremise).
  res.gross = find_gross_errors(cur.space, cur.m_c, opts.gross);
  {
    ResidualSpace traced = cur.space;
    if (res.gross.found()) traced.add(reduce_columns(cfg, res.gross.columns));
    res.trace = trace_residual(traced, cur.m_c, RecordedVariables{t_s, opts.recorded_direction, {}},
                               opts.trace);
  }
  // Each step below separates the readings afresh, with its own σ̂ and covariance: what the
  // steps before it carried (CarriedTerm) is carried again, as it is, not as the excess of the
  // refined u over the raw one (that excess is negative, and the term was dropped, whenever the
  // fresh σ̂ fell below the raw one: the gross errors' sizes under a non-linearity, the effects'
  // covariance under a gross error).
  Eigen::VectorXd v_effects = Eigen::VectorXd::Zero(P);
  if (!M.effects.empty()) {
    // report_model's term, pointwise, as it went into `after`.
    const CarriedTerm& t = current.term;
    if (!t.empty()) v_effects = (t.G_S * t.K).cwiseProduct(t.G_S).rowwise().sum().cwiseMax(0.0);
  }
  Eigen::VectorXd v_gross_S, v_gross_g, v_gross_f;  // what the gross-error step carried, pointwise
  if (res.gross.found() && opts.remove_gross_errors) {
    FourSensorResult without = separate_without_gross_errors(cfg, res.m_corrected_um, &res.gross,
                                                             res.after, opts.solve, opts.decision);
    res.m_corrected_um -= res.gross.correction_um;
    res.gross_removed = true;
    v_gross_S = without.u_S_um.array().square();
    v_gross_g = without.u_gamma_rad.array().square();
    v_gross_f = without.u_f_um.array().square();
    carry(without, current.term);
    res.after = std::move(without);
  }
  if (opts.correct_nonlinearity) {
    FourSensorResult without =
        separate_without_nonlinearity(cfg, res.m_corrected_um, res.trace, res.after, opts.solve,
                                      &res.nonlinearity, opts.decision);
    if (res.nonlinearity.detected) {
      carry(without, current.term);
      if (res.gross_removed) {
        // The gross-error step's own term, pointwise: its u over the fresh separation of the
        // same readings (its low-rank form stays inside gross_errors.cpp, so the covariance
        // object does not get it here).
        const FourSensorResult fresh = separate_four_sensor(cfg, res.m_corrected_um, opts.solve);
        auto add = [](Eigen::VectorXd& u, const Eigen::VectorXd& with2,
                      const Eigen::VectorXd& fresh_u) {
          if (u.size() == with2.size() && u.size() == fresh_u.size())
            u = (u.array().square() + (with2.array() - fresh_u.array().square()).max(0.0)).sqrt();
        };
        add(without.u_S_um, v_gross_S, fresh.u_S_um);
        add(without.u_gamma_rad, v_gross_g, fresh.u_gamma_rad);
        add(without.u_f_um, v_gross_f, fresh.u_f_um);
      }
      if (res.nonlinearity.applied)
        res.m_corrected_um -=
            res.nonlinearity.c2_per_um *
            (res.m_corrected_um.array() - res.nonlinearity.mid_um).square().matrix();
      res.after = std::move(without);
    }
  }
  // The gauge floor (refine.hpp RefineResult::u_S_gauge_um).
  res.u_S_effects_um = v_effects.cwiseSqrt();
  res.u_S_gauge_um = Eigen::VectorXd::Zero(P);
  if (res.after.covariance && res.before.covariance &&
      res.after.covariance != res.before.covariance) {
    const CarriedTerm floor = gauge_floor(cfg, res.before, res.after);
    res.u_S_gauge_um = carry(res.after, floor).cwiseSqrt();
  }
  res.u_S_declared_um = Eigen::VectorXd::Zero(P);
  if (!opts.declared.empty()) {
    const DeclaredTerm dt = declared_term(cfg, M, cur, res.before, opts, library);
    res.declared_notes = dt.notes;
    if (dt.K.size() > 0) {
      // A fresh separation when `after` is still `before`'s (same covariance object): the term
      // must not reach the raw result.
      if (res.after.covariance && res.after.covariance == res.before.covariance) {
        FourSensorResult fresh = separate_four_sensor(cfg, res.m_corrected_um, opts.solve);
        fresh.S_um = res.after.S_um;
        fresh.gamma_rad = res.after.gamma_rad;
        fresh.f_um = res.after.f_um;
        res.after = std::move(fresh);
      }
      auto variance = [&](const Eigen::MatrixXd& D) {
        return Eigen::VectorXd((D * dt.K).cwiseProduct(D).rowwise().sum().cwiseMax(0.0));
      };
      const Eigen::VectorXd vS = variance(dt.GS), vg = variance(1e-6 * dt.Gg), vf = variance(dt.Gf);
      auto widen = [](Eigen::VectorXd& u, const Eigen::VectorXd& v) {
        if (u.size() == v.size()) u = (u.array().square() + v.array()).sqrt();
      };
      widen(res.after.u_S_um, vS);
      widen(res.after.u_gamma_rad, vg);
      widen(res.after.u_f_um, vf);
      res.u_S_declared_um = vS.cwiseSqrt();
      if (res.after.covariance)
        res.after.covariance->add_low_rank(dt.GS, 1e-6 * dt.Gg, dt.Gf, dt.K);
    }
  }
  return res;
}

}  // namespace errsep::core

#include "errsep/core/sequence_refine.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "errsep/core/effect_thermal_drift.hpp"
#include "errsep/core/effect_traverse.hpp"
#include "errsep/core/four_sensor_system.hpp"
#include "errsep/core/refine.hpp"
#include "errsep/core/step_decision.hpp"

namespace errsep::core {

const char* to_string(SequenceEffectKind k) {
  switch (k) {
    case SequenceEffectKind::drift:
      return "drift";
    case SequenceEffectKind::thermal:
      return "thermal drift";
    case SequenceEffectKind::traverse:
      return "non-repeating traverse";
  }
  return "unknown";
}

bool SequenceRefineOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(alpha > 0 && alpha < 1))
    return fail("alpha = " + std::to_string(alpha) + ": must be in (0, 1)");
  if (max_effects < 0) return fail("max_effects must be >= 0");
  if (!(identifiability_tol > 0 && identifiability_tol < 1))
    return fail("identifiability_tol must be in (0, 1)");
  if (!(weak_direction_sv >= 0 && weak_direction_sv < 1))
    return fail("weak_direction_sv must be in [0, 1)");
  if (!(undetermined_S_max > 0)) return fail("undetermined_S_max must be > 0");
  if (thermal_grid < 1) return fail("thermal_grid must be >= 1");
  if (traverse_degree < 1) return fail("traverse_degree must be >= 1");
  return true;
}

namespace {

// The base design of the file comment: columns f (gauge basis, N − 3), S (P), γ (P, in µrad so
// that its columns are of the order of the others), e (free traverses).
struct Base {
  Eigen::MatrixXd X;
  int nf = 0, P = 0, T = 0;
  std::vector<int> e_column;  // per traverse: column of its e, or -1 (held at 0)
  Eigen::MatrixXd Bf;         // N × (N − 3)
};

Base base_design(const FourSensorConfig& cfg, const ScanSequence& seq) {
  std::string why;
  if (!cfg.is_valid(&why)) throw std::invalid_argument("invalid configuration: " + why);
  if (!seq.is_valid(&why)) throw std::invalid_argument("invalid scan sequence: " + why);
  Base b;
  const int N = cfg.N;
  b.P = cfg.positions();
  b.T = seq.size();
  b.nf = N - 3;
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(3, N);
  C(0, 0) = 1.0;
  C(1, N - 1) = 1.0;
  C.row(2) = reference_bow(cfg).transpose();
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(C, Eigen::ComputeFullV);
  b.Bf = svd.matrixV().rightCols(N - 3);
  // Zero adjustments: traverse 1 and the first traverse of configuration 4 are the gauge.
  std::array<int, 4> first{-1, -1, -1, -1};
  b.e_column.assign(static_cast<std::size_t>(b.T), -1);
  int col = b.nf + 2 * b.P;
  for (int k = 0; k < b.T; ++k) {
    const int c = seq.traverses[static_cast<std::size_t>(k)].configuration;
    const auto sc = static_cast<std::size_t>(c);
    const bool is_first = first[sc] < 0;
    if (is_first) first[sc] = k;
    if (is_first && (c == 0 || c == 3)) continue;  // held at 0
    if (!is_first && seq.repeat_keeps_zero) {
      b.e_column[static_cast<std::size_t>(k)] = b.e_column[static_cast<std::size_t>(first[sc])];
      continue;
    }
    b.e_column[static_cast<std::size_t>(k)] = col++;
  }
  const auto off = cfg.offsets_samples();
  const auto O = cfg.offsets_mm();
  b.X = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(b.P) * b.T, col);
  for (int k = 0; k < b.T; ++k) {
    const auto c =
        static_cast<std::size_t>(seq.traverses[static_cast<std::size_t>(k)].configuration);
    for (int n = 0; n < b.P; ++n) {
      const Eigen::Index r = static_cast<Eigen::Index>(k) * b.P + n;
      b.X.row(r).head(b.nf) = b.Bf.row(n + off[c]);  // Eq. (1): f(x_n + O_c)
      b.X(r, b.nf + n) = 1.0;                        // S(x_n)
      b.X(r, b.nf + b.P + n) = 1e-3 * O[c];          // O_c·γ(x_n), γ in µrad
      const int ec = b.e_column[static_cast<std::size_t>(k)];
      if (ec >= 0) b.X(r, ec) = 1.0;
    }
  }
  return b;
}

Eigen::VectorXd flatten(const Eigen::MatrixXd& m) {
  Eigen::VectorXd y(m.size());
  for (Eigen::Index k = 0; k < m.cols(); ++k)
    y.segment(k * m.rows(), m.rows()) = m.col(k);
  return y;
}

Eigen::MatrixXd thin_q(const Eigen::MatrixXd& X) {
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(X);
  return qr.householderQ() * Eigen::MatrixXd::Identity(X.rows(), X.cols());
}

// Columns projected on the complement of span(Q), scaled to unit norm before projection; the SVD
// of the result.
struct Projected {
  Eigen::VectorXd D, sv;
  Eigen::MatrixXd U, V;
  int identifiable = 0;  // above tol
  int strong = 0;        // above weak_sv: determined well enough to be fitted
};

Projected project(const Eigen::MatrixXd& Q, const Eigen::MatrixXd& J, double tol, double weak_sv) {
  Projected p;
  p.D.resize(J.cols());
  Eigen::MatrixXd Js = J;
  for (Eigen::Index c = 0; c < J.cols(); ++c) {
    p.D(c) = J.col(c).norm() > 0 ? J.col(c).norm() : 1.0;
    Js.col(c) /= p.D(c);
  }
  const Eigen::MatrixXd RJ = Js - Q * (Q.transpose() * Js);
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(RJ, Eigen::ComputeThinU | Eigen::ComputeFullV);
  p.sv = svd.singularValues();
  p.U = svd.matrixU();
  p.V = svd.matrixV();
  for (Eigen::Index j = 0; j < p.sv.size(); ++j)
    if (p.sv(j) > tol) ++p.identifiable;
  for (Eigen::Index j = 0; j < p.sv.size(); ++j)
    if (p.sv(j) > std::max(tol, weak_sv)) ++p.strong;
  return p;
}

}  // namespace

SequenceFit fit_four_sensor_sequence(const FourSensorConfig& cfg, const ScanSequence& seq,
                                     const Eigen::MatrixXd& m_um, const Eigen::MatrixXd& extra) {
  const Base b = base_design(cfg, seq);
  if (m_um.rows() != b.P || m_um.cols() != b.T)
    throw std::invalid_argument("readings must be P x T (" + std::to_string(b.P) + " x " +
                                std::to_string(b.T) + "), got " + std::to_string(m_um.rows()) +
                                " x " + std::to_string(m_um.cols()));
  if (extra.size() != 0 && extra.rows() != b.X.rows())
    throw std::invalid_argument("extra columns must have P*T rows");
  const Eigen::Index nb = b.X.cols(), q = extra.size() ? extra.cols() : 0;
  Eigen::MatrixXd X(b.X.rows(), nb + q);
  X.leftCols(nb) = b.X;
  if (q) X.rightCols(q) = extra;
  const Eigen::VectorXd y = flatten(m_um);
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(X);
  const Eigen::VectorXd beta = qr.solve(y);
  const Eigen::VectorXd r = y - X * beta;
  SequenceFit out;
  out.dof = static_cast<int>(X.rows() - X.cols());
  out.rss_um2 = r.squaredNorm();
  out.sigma_um = out.dof > 0 ? std::sqrt(out.rss_um2 / out.dof) : 0.0;
  out.f_um = b.Bf * beta.head(b.nf);
  out.S_um = beta.segment(b.nf, b.P);
  out.gamma_rad = 1e-6 * beta.segment(b.nf + b.P, b.P);
  out.e_um = Eigen::VectorXd::Zero(b.T);
  for (int k = 0; k < b.T; ++k)
    if (b.e_column[static_cast<std::size_t>(k)] >= 0)
      out.e_um(k) = beta(b.e_column[static_cast<std::size_t>(k)]);
  out.extra_coefficients = beta.tail(q);
  out.residual_um.resize(b.P, b.T);
  for (int k = 0; k < b.T; ++k)
    out.residual_um.col(k) = r.segment(static_cast<Eigen::Index>(k) * b.P, b.P);
  // Cov(β) = σ̂²·R⁻¹R⁻ᵀ; the S block about its best-fit bow: Π·Cov_SS·Π.
  const Eigen::MatrixXd R = qr.matrixQR().topRows(X.cols()).triangularView<Eigen::Upper>();
  const Eigen::MatrixXd Rinv_S = R.triangularView<Eigen::Upper>()
                                     .solve(Eigen::MatrixXd::Identity(X.cols(), X.cols()))
                                     .middleRows(b.nf, b.P);
  const Eigen::MatrixXd Pi = remove_polynomial(Eigen::MatrixXd::Identity(b.P, b.P), 2);
  const Eigen::MatrixXd A = Pi * Rinv_S;  // Π·(R⁻¹)_S·: Cov = σ̂²·A·Aᵀ
  out.u_S_um = out.sigma_um * A.rowwise().norm();
  return out;
}

SequenceEffectColumns sequence_effect_columns(SequenceEffectKind kind, const FourSensorConfig& cfg,
                                              const ScanSequence& seq, double tau_s,
                                              int traverse_degree) {
  std::string why;
  if (!cfg.is_valid(&why)) throw std::invalid_argument("invalid configuration: " + why);
  if (!seq.is_valid(&why)) throw std::invalid_argument("invalid scan sequence: " + why);
  const int P = cfg.positions(), T = seq.size();
  const Eigen::MatrixXd t = seq.times_s(cfg);
  const double t0 = t.minCoeff();
  SequenceEffectColumns out;
  out.kind = kind;
  char buf[160];
  auto config_of = [&](int k) { return seq.traverses[static_cast<std::size_t>(k)].configuration; };
  switch (kind) {
    case SequenceEffectKind::drift:
    case SequenceEffectKind::thermal: {
      if (kind == SequenceEffectKind::thermal && !(tau_s > 0))
        throw std::invalid_argument("thermal drift needs tau_s > 0");
      out.J = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(P) * T, 4);
      for (int k = 0; k < T; ++k)
        for (int n = 0; n < P; ++n) {
          const double tt = t(n, k) - t0;
          out.J(static_cast<Eigen::Index>(k) * P + n, config_of(k)) =
              kind == SequenceEffectKind::drift ? tt : 1.0 - std::exp(-tt / tau_s);
        }
      if (kind == SequenceEffectKind::drift)
        std::snprintf(buf, sizeof buf, "linear drift per configuration (a_c*t)");
      else
        std::snprintf(buf, sizeof buf, "thermal drift per configuration, tau %.3g s", tau_s);
      break;
    }
    case SequenceEffectKind::traverse: {
      // The Legendre basis of TraverseEffect (degrees 1..K), scaled per traverse by its time.
      const Eigen::MatrixXd phi = TraverseEffect(1, traverse_degree).basis(cfg);
      const Eigen::VectorXd mid = t.colwise().mean().transpose();
      const double span = std::max(mid.maxCoeff() - mid(0), 1e-9);
      out.J.resize(static_cast<Eigen::Index>(P) * T, phi.cols());
      for (int k = 0; k < T; ++k)
        out.J.middleRows(static_cast<Eigen::Index>(k) * P, P) = ((mid(k) - mid(0)) / span) * phi;
      std::snprintf(buf, sizeof buf,
                    "S changing in proportion to time between traverses, Legendre P1..P%d",
                    traverse_degree);
      break;
    }
  }
  out.description = buf;
  return out;
}

namespace {

double representative_tau_s(const FourSensorConfig& cfg, const ScanSequence& seq, int grid) {
  const auto g = ThermalDriftEffect::tau_grid_s(seq.times_s(cfg), grid);
  return g[g.size() / 2];
}

// The widening of the header's file comment, for each detected-but-unidentifiable effect, on the
// final model (base + added effects): res.after.u_S_um and the candidates' u_S_added_um.
void widen_for_unidentifiable(const FourSensorConfig& cfg, const ScanSequence& seq, const Base& b,
                              const Eigen::MatrixXd& extra, const Eigen::VectorXd& y,
                              const SequenceRefineOptions& o, SequenceRefineResult& res) {
  res.u_S_widening_um = Eigen::VectorXd::Zero(b.P);
  if (res.detected_not_identifiable.empty()) return;
  Eigen::MatrixXd X(b.X.rows(), b.X.cols() + extra.cols());
  X << b.X, extra;
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(X);
  const Eigen::MatrixXd Q = qr.householderQ() * Eigen::MatrixXd::Identity(X.rows(), X.cols());
  const Eigen::MatrixXd R = qr.matrixQR().topRows(X.cols()).triangularView<Eigen::Upper>();
  const Eigen::MatrixXd Pi = remove_polynomial(Eigen::MatrixXd::Identity(b.P, b.P), 2);
  const Eigen::VectorXd r = y - Q * (Q.transpose() * y);
  const double s2_noise = res.after.sigma_um * res.after.sigma_um;
  Eigen::VectorXd var = Eigen::VectorXd::Zero(b.P);
  for (auto& c : res.detected_not_identifiable) {
    const auto cols =
        sequence_effect_columns(c.kind, cfg, seq, c.tau_s > 0 ? c.tau_s : 40.0, o.traverse_degree);
    const Projected pj = project(Q, cols.J, o.identifiability_tol, o.weak_direction_sv);
    const Eigen::MatrixXd Js = cols.J * pj.D.cwiseInverse().asDiagonal();
    const Eigen::MatrixXd toS =
        Pi * R.triangularView<Eigen::Upper>().solve(Q.transpose() * Js).middleRows(b.nf, b.P);
    // The directions that size the effect: the well-determined ones, or every seen one when the
    // plan determines none well (their noise is removed from the squared coefficients).
    const Eigen::Index q = cols.J.cols();
    const Eigen::Index ks = pj.strong > 0 ? pj.strong : pj.identifiable;
    Eigen::VectorXd coef = Eigen::VectorXd::Zero(ks);
    double s2 = 0.0;
    for (Eigen::Index j = 0; j < ks; ++j) {
      const double u = pj.U.col(j).dot(r);
      // The coefficient's size plus its standard uncertainty σ̂/svⱼ: the size the data do not
      // exclude at one standard uncertainty (the fitted size alone under-covers when the one
      // seen direction is small by chance: closing pass, drift, coverage 0.83 of the detected
      // runs instead of 0.96).
      const double c2 = std::pow(std::abs(u) + std::sqrt(s2_noise), 2) / (pj.sv(j) * pj.sv(j));
      coef(j) = std::copysign(std::sqrt(c2), u);
      s2 += c2;
    }
    if (ks > 0) s2 /= static_cast<double>(ks);
    const Eigen::VectorXd seen = toS * pj.V.leftCols(ks) * coef;
    const Eigen::VectorXd unseen = (toS * pj.V.rightCols(q - ks)).rowwise().squaredNorm();
    const Eigen::VectorXd add = seen.cwiseAbs2() + s2 * unseen;
    c.u_S_added_um = std::sqrt(add.mean());
    var += add;
  }
  res.u_S_widening_um = var.cwiseSqrt();
  res.after.u_S_um = (res.after.u_S_um.cwiseAbs2() + var).cwiseSqrt();
}

}  // namespace

std::vector<SequenceIdentifiability> sequence_identifiability(const FourSensorConfig& cfg,
                                                              const ScanSequence& seq,
                                                              const SequenceRefineOptions& o) {
  const Base b = base_design(cfg, seq);
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(b.X);
  const Eigen::MatrixXd Q = qr.householderQ() * Eigen::MatrixXd::Identity(b.X.rows(), b.X.cols());
  const Eigen::MatrixXd R = qr.matrixQR().topRows(b.X.cols()).triangularView<Eigen::Upper>();
  const Eigen::MatrixXd Pi = remove_polynomial(Eigen::MatrixXd::Identity(b.P, b.P), 2);
  const double tau = representative_tau_s(cfg, seq, o.thermal_grid);
  std::vector<SequenceIdentifiability> out;
  for (auto kind :
       {SequenceEffectKind::drift, SequenceEffectKind::thermal, SequenceEffectKind::traverse}) {
    const auto cols = sequence_effect_columns(kind, cfg, seq, tau, o.traverse_degree);
    const Projected pj = project(Q, cols.J, o.identifiability_tol, o.weak_direction_sv);
    SequenceIdentifiability id;
    id.kind = kind;
    id.parameters = static_cast<int>(cols.J.cols());
    id.identifiable = pj.identifiable;
    id.strong = pj.strong;
    id.relative_sv = pj.sv;
    // What the base fit puts into S from readings J·D⁻¹·v: (R⁻¹Qᵀ)_S·J·D⁻¹·v, after the gauge.
    const Eigen::MatrixXd Js = cols.J * pj.D.cwiseInverse().asDiagonal();
    const Eigen::MatrixXd toS =
        Pi * R.triangularView<Eigen::Upper>().solve(Q.transpose() * Js).middleRows(b.nf, b.P);
    // A unit column spread over the P·T readings has RMS 1/sqrt(P·T); the RMS change of S it
    // causes is |toS·v|/sqrt(P): the gain from the effect's reading RMS to S's is |toS·v|·sqrt(T).
    const Eigen::Index k0 = id.parameters - pj.strong;
    if (k0 > 0) {
      const Eigen::MatrixXd Sh = toS * pj.V.rightCols(k0);
      id.undetermined_S_gain =
          Eigen::JacobiSVD<Eigen::MatrixXd>(Sh).singularValues()(0) * std::sqrt(double(b.T));
    }
    id.identifiable_from_plan = id.undetermined_S_gain <= o.undetermined_S_max;
    out.push_back(id);
  }
  return out;
}

bool SequenceRefineResult::identified(SequenceEffectKind k) const {
  return std::any_of(added.begin(), added.end(), [k](const auto& c) { return c.kind == k; });
}

bool SequenceRefineResult::identifiable_from_plan(SequenceEffectKind k) const {
  return std::any_of(plan_identifiability.begin(), plan_identifiability.end(),
                     [k](const auto& c) { return c.kind == k && c.identifiable_from_plan; });
}

SequenceRefineResult refine_four_sensor_sequence(const FourSensorConfig& cfg,
                                                 const ScanSequence& seq,
                                                 const Eigen::MatrixXd& m_um,
                                                 const SequenceRefineOptions& o) {
  std::string why;
  if (!o.is_valid(&why)) throw std::invalid_argument("invalid refine options: " + why);
  SequenceRefineResult res;
  res.plan = seq.name;
  res.before = fit_four_sensor_sequence(cfg, seq, m_um);
  res.plan_identifiability = sequence_identifiability(cfg, seq, o);
  const Base b = base_design(cfg, seq);
  const Eigen::VectorXd y = flatten(m_um);
  const auto taus = ThermalDriftEffect::tau_grid_s(seq.times_s(cfg), o.thermal_grid);
  const std::vector<SequenceEffectKind> kinds = {
      SequenceEffectKind::drift, SequenceEffectKind::thermal, SequenceEffectKind::traverse};
  Eigen::MatrixXd extra(b.X.rows(), 0);
  for (int round = 0; round < o.max_effects; ++round) {
    Eigen::MatrixXd X(b.X.rows(), b.X.cols() + extra.cols());
    X << b.X, extra;
    const Eigen::MatrixXd Q = thin_q(X);
    const Eigen::VectorXd r = y - Q * (Q.transpose() * y);
    const double rss = r.squaredNorm();
    const int dof = static_cast<int>(X.rows() - X.cols());
    std::vector<SequenceCandidate> scored;
    std::vector<Eigen::MatrixXd> directions;
    for (auto kind : kinds) {
      if (res.identified(kind)) continue;
      SequenceCandidate best;
      best.kind = kind;
      const bool identifiable = res.identifiable_from_plan(kind);
      Eigen::MatrixXd best_dirs;
      const std::vector<double> grid =
          kind == SequenceEffectKind::thermal ? taus : std::vector<double>{0.0};
      for (double tau : grid) {
        const auto cols = sequence_effect_columns(kind, cfg, seq, tau, o.traverse_degree);
        const Projected pj = project(Q, cols.J, o.identifiability_tol, o.weak_direction_sv);
        // An effect the plan identifies keeps its weakly determined directions too: by the
        // plan's measure they do not reach S, and without them the effect is incomplete (a
        // drift fitted on three of its four directions leaves a residual another effect takes).
        // One it does not is scored on its well-determined directions, or, when the plan
        // determines none well (the single plan's non-repeating traverse), on every direction
        // the data see: the F-test is exact on any of them, and a suspected effect must be told.
        const int kid = identifiable || pj.strong == 0 ? pj.identifiable : pj.strong;
        if (kid == 0 || dof - kid <= 0) continue;
        double d = 0.0;
        for (int j = 0; j < kid; ++j)
          d += std::pow(pj.U.col(j).dot(r), 2);
        const double F = (d / kid) / ((rss - d) / (dof - kid));
        const double p = f_test_p_value(F, kid, dof - kid);
        if (best_dirs.size() == 0 || p < best.p_value) {
          best.description = cols.description;
          best.tau_s = kind == SequenceEffectKind::thermal ? tau : 0.0;
          best.identifiable = kid;
          best.F = F;
          best.p_value = p;
          best.delta_rss_um2 = d;
          best_dirs = cols.J * pj.D.cwiseInverse().asDiagonal() * pj.V.leftCols(kid);
        }
      }
      // Šidák over the τ grid (neighbouring values are correlated: conservative).
      if (grid.size() > 1)
        best.p_value = -std::expm1(static_cast<double>(grid.size()) * std::log1p(-best.p_value));
      scored.push_back(best);
      directions.push_back(best_dirs);
    }
    if (round == 0) res.first_round = scored;
    if (scored.empty()) break;
    // Only an effect the plan can identify is added: fitting the visible part of one it cannot
    // would leave (or put) its invisible part in S.  A significant one is reported instead.
    const double threshold = o.alpha / static_cast<double>(scored.size());
    std::size_t ib = scored.size();
    for (std::size_t i = 0; i < scored.size(); ++i) {
      if (!(scored[i].p_value < threshold) || directions[i].size() == 0) continue;
      if (!res.identifiable_from_plan(scored[i].kind)) {
        if (std::none_of(res.detected_not_identifiable.begin(), res.detected_not_identifiable.end(),
                         [&](const auto& c) { return c.kind == scored[i].kind; }))
          res.detected_not_identifiable.push_back(scored[i]);
        continue;
      }
      if (ib == scored.size() || scored[i].p_value < scored[ib].p_value) ib = i;
    }
    if (ib == scored.size()) break;
    // Attribution: when another significant candidate explains the chosen one's signal (the
    // chosen is no longer significant once the other is in the model), the data cannot tell
    // which effect it is, and the two change S differently (a drift leaves S alone, a
    // non-repeating S is the change of S): nothing is applied, the ambiguity is reported.
    // A linear drift is the long-τ limit of the thermal one (a·t = lim A·(1 − exp(−t/τ)) with
    // A/τ = a): one family, not rivals.
    auto is_drift = [](SequenceEffectKind k) {
      return k == SequenceEffectKind::drift || k == SequenceEffectKind::thermal;
    };
    std::string rival;
    for (std::size_t i = 0; i < scored.size(); ++i) {
      if (i == ib || !(scored[i].p_value < threshold) || directions[i].size() == 0) continue;
      if (is_drift(scored[i].kind) && is_drift(scored[ib].kind)) continue;
      Eigen::MatrixXd Xr(X.rows(), X.cols() + directions[i].cols());
      Xr << X, directions[i];
      const Eigen::MatrixXd Qr = thin_q(Xr);
      const Eigen::VectorXd rr = y - Qr * (Qr.transpose() * y);
      const Projected pb = project(Qr, directions[ib], o.identifiability_tol, 0.0);
      const int kb = pb.identifiable, dof_r = static_cast<int>(Xr.rows() - Xr.cols()) - kb;
      double d = 0.0;
      for (int j = 0; j < kb; ++j)
        d += std::pow(pb.U.col(j).dot(rr), 2);
      const double F = kb > 0 && dof_r > 0 ? (d / kb) / ((rr.squaredNorm() - d) / dof_r) : 0.0;
      if (!(f_test_p_value(F, kb, dof_r) < threshold)) rival = to_string(scored[i].kind);
    }
    if (!rival.empty()) {
      char amb[300];
      std::snprintf(amb, sizeof amb,
                    "%s or %s: detected (F = %.3g, p = %.2g) but not separable from this plan "
                    "(%s): either explains the other's signal; not applied.",
                    to_string(scored[ib].kind), rival.c_str(), scored[ib].F, scored[ib].p_value,
                    seq.name.c_str());
      res.ambiguous.push_back(amb);
      break;
    }
    Eigen::MatrixXd grown(extra.rows(), extra.cols() + directions[ib].cols());
    grown << extra, directions[ib];
    extra = grown;
    res.added.push_back(scored[ib]);
  }
  res.after = extra.cols() ? fit_four_sensor_sequence(cfg, seq, m_um, extra) : res.before;
  widen_for_unidentifiable(cfg, seq, b, extra, y, o, res);
  char buf[600];
  for (const auto& a : res.added) {
    std::snprintf(buf, sizeof buf, "%s identified: %s, %d direction(s), F = %.3g, p = %.2g",
                  to_string(a.kind), a.description.c_str(), a.identifiable, a.F, a.p_value);
    res.report.push_back(buf);
  }
  res.report.insert(res.report.end(), res.ambiguous.begin(), res.ambiguous.end());
  // Only an effect the data suggest gets a line: "not identifiable" on every clean run of a
  // plan would be noise the user learns to ignore.
  for (const auto& id : res.plan_identifiability)
    if (!id.identifiable_from_plan) {
      std::string detected;
      for (const auto& c : res.detected_not_identifiable)
        if (c.kind == id.kind) {
          char d[160];
          std::snprintf(d, sizeof d,
                        " Detected (F = %.3g, p = %.2g), not applied; adds %.2g um (RMS) to u_S.",
                        c.F, c.p_value, c.u_S_added_um);
          detected = d;
        }
      if (detected.empty()) continue;
      std::snprintf(buf, sizeof buf,
                    "%s: not identifiable from this plan (%s): %d of %d parameter directions "
                    "determined; the rest move S by up to %.2g um per um of the effect in the "
                    "readings.%s Measure with %s.",
                    to_string(id.kind), seq.name.c_str(), id.strong, id.parameters,
                    id.undetermined_S_gain, detected.c_str(),
                    // What identifies it (sequence_identifiability on Zhao 2019's geometry): a
                    // drift needs each configuration forward and back; a change of S between
                    // traverses shows in any repeated configuration.
                    id.kind == SequenceEffectKind::traverse
                        ? "a closing pass or reversed traverses"
                        : "reversed traverses (each configuration forward and back)");
      res.report.push_back(buf);
    }
  return res;
}

}  // namespace errsep::core

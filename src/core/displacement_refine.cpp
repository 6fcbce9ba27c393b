#include "errsep/core/displacement_refine.hpp"
#include "errsep/core/golden_section.hpp"

#include "displacement_effect_selection.hpp"

#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace errsep::core {
namespace {

Eigen::VectorXd flatten(const Eigen::MatrixXd& m) {
  return Eigen::Map<const Eigen::VectorXd>(m.data(), m.size());
}

/// A scan of zeros on the grid (sensor 0 repeated or not).
TwoAxisScan zero_scan(const Eigen::VectorXd& x_mm, const Eigen::VectorXd& y_mm, bool s0_repeat) {
  TwoAxisScan s;
  s.x_mm = x_mm;
  s.y_mm = y_mm;
  const Eigen::MatrixXd z = Eigen::MatrixXd::Zero(x_mm.size(), y_mm.size());
  for (auto* m : {&s.s0_1_um, &s.s1_1_um, &s.s1_2_um, &s.s2_1_um, &s.s2_2_um, &s.s3_1_um,
                  &s.s3_2_um, &s.s4_1_um, &s.s4_2_um})
    *m = z;
  if (s0_repeat) s.s0_2_um = z;
  return s;
}

/// The scan differences D_1 … D_4 (then D_0 when sensor 0 is repeated), stacked column major.
Eigen::VectorXd scan_differences(const TwoAxisScan& s) {
  const Eigen::Index N = s.s1_1_um.size();
  const bool rep = s.s0_2_um.size() != 0;
  Eigen::VectorXd d((rep ? 5 : 4) * N);
  d.segment(0, N) = flatten(s.s1_2_um - s.s1_1_um);
  d.segment(N, N) = flatten(s.s2_2_um - s.s2_1_um);
  d.segment(2 * N, N) = flatten(s.s3_2_um - s.s3_1_um);
  d.segment(3 * N, N) = flatten(s.s4_2_um - s.s4_1_um);
  if (rep) d.segment(4 * N, N) = flatten(s.s0_2_um - s.s0_1_um);
  return d;
}

/// P: each difference minus its group mean (sensors 1, 2: the row x_i over every y; sensors 3, 4:
/// the column y_j over every x; sensor 0: all points), in place on stacked columns.
void project(Eigen::Ref<Eigen::MatrixXd> d, Eigen::Index nx, Eigen::Index ny) {
  const Eigen::Index N = nx * ny;
  for (Eigen::Index c = 0; c < d.cols(); ++c)
    for (Eigen::Index k = 0; k * N < d.rows(); ++k) {
      Eigen::Map<Eigen::MatrixXd> g(d.col(c).data() + k * N, nx, ny);
      if (k < 2)
        g.colwise() -= g.rowwise().mean();  // row i: mean over j
      else if (k < 4)
        g.rowwise() -= g.colwise().mean();  // column j: mean over i
      else
        g.array() -= g.mean();
    }
}

std::string family_hint(const std::string& family, bool s0_repeat) {
  if (family == "drift")
    return "scan 2 in the order of scan 1 makes the scan difference one constant per sensor, "
           "absorbed by r's slope and sensor 0's offset; run scan 2 y fastest (and backwards)";
  if (family == "tilt" && !s0_repeat)
    return "only sensor 0's repeat sees it: record sensor 0 in scan 2";
  return "its scan differences are absorbed by the joint model";
}

/// The residual columns P·E of an effect (and, in *diff, the scan differences E).
Eigen::MatrixXd residual_columns(const DisplacementEffect& e, const TwoAxisScan& zero,
                                 const TwoAxisScanOrder& order, Eigen::MatrixXd* diff = nullptr) {
  const auto k = static_cast<Eigen::Index>(e.parameters.size());
  Eigen::MatrixXd d(scan_differences(zero).size(), k);
  for (Eigen::Index j = 0; j < k; ++j) {
    TwoAxisScan u = zero;
    add_disturbance(u, e.unit(j), order);
    d.col(j) = scan_differences(u);
  }
  if (diff) *diff = d;
  project(d, zero.s1_1_um.rows(), zero.s1_1_um.cols());
  return d;
}

/// Fills the effect's residual columns, sensitivities and identifiability.
void complete_effect(DisplacementEffect& e, const TwoAxisScan& zero, const TwoAxisScanOrder& order,
                     const TwoAxisOptions& separation, double tolerance) {
  const auto k = static_cast<Eigen::Index>(e.parameters.size());
  const Eigen::Index N = zero.s1_1_um.size();
  Eigen::MatrixXd diff;
  e.residual_columns = residual_columns(e, zero, order, &diff);
  for (int r = 0; r < 2; ++r) {
    e.d_w[r].resize(N, k);
    e.d_m_w[r].resize(N, k);
  }
  for (Eigen::Index j = 0; j < k; ++j) {
    TwoAxisScan u = zero;
    add_disturbance(u, e.unit(j), order);
    for (int r = 0; r < 2; ++r) {
      TwoAxisOptions so = separation;
      so.rotation = r ? RotationCorrection::on : RotationCorrection::off;
      so.displacement_sigma_mm = 0;
      const TwoAxisResult sep = separate_two_axis(u, so);
      e.d_w[r].col(j) = -flatten(sep.w_um);
      e.d_m_w[r].col(j) = -flatten(sep.m_w_um);
    }
  }
  // Identifiability: residual columns scaled by their difference column's norm.
  Eigen::VectorXd scale(k);
  bool zero_column = false;
  for (Eigen::Index j = 0; j < k; ++j) {
    const double n = diff.col(j).norm();
    zero_column = zero_column || !(n > 0);
    scale(j) = n > 0 ? 1.0 / n : 0.0;
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(e.residual_columns * scale.asDiagonal());
  e.relative_singular_value = zero_column ? 0.0 : svd.singularValues().minCoeff();
  e.identifiable = e.relative_singular_value > tolerance;
  // How well the plan determines what each group does to w (no data): every reading at σ = 1, a
  // scan difference's variance 2; C = 2(XᵀX)⁻¹ of the residual columns, the w change of the group
  // (gauge: its constant removed) carried through the group's block of C (rotation off).
  e.group_u_w_per_sigma.clear();
  if (!e.identifiable) return;
  const Eigen::MatrixXd C = 2.0 * (e.residual_columns.transpose() * e.residual_columns)
                                      .completeOrthogonalDecomposition()
                                      .pseudoInverse();
  for (const auto& g : e.groups) {
    const auto kg = static_cast<Eigen::Index>(g.size());
    Eigen::MatrixXd gw(N, kg), cg(kg, kg);
    for (Eigen::Index a = 0; a < kg; ++a) {
      const auto ia = g[static_cast<std::size_t>(a)];
      gw.col(a) = e.d_w[0].col(ia).array() - e.d_w[0].col(ia).mean();
      for (Eigen::Index b = 0; b < kg; ++b)
        cg(a, b) = C(ia, g[static_cast<std::size_t>(b)]);
    }
    e.group_u_w_per_sigma.push_back(
        std::sqrt(std::max(0.0, (gw * cg).cwiseProduct(gw).rowwise().sum().mean())));
  }
}

/// Sensor 0; the reference X sensors 1, 2; the reference Y sensors 3, 4.
const std::vector<std::vector<int>> kSensorGroups = {{0}, {1, 2}, {3, 4}};

/// "sensor 0", "sensors 1-2" (thermal's dtau_s, index 5, is in every group and not named).
std::string group_name(std::vector<int> g) {
  std::erase_if(g, [](int i) { return i >= 5; });
  if (g.size() == 1) return "sensor " + std::to_string(g[0]);
  return "sensors " + std::to_string(g.front()) + "-" + std::to_string(g.back());
}

/// "3.3-170" (or "0.78" when both ends print the same) with the printf format `f`.
std::string format_range(double lo, double hi, const char* f) {
  char a[32], b[32];
  std::snprintf(a, sizeof a, f, lo);
  std::snprintf(b, sizeof b, f, hi);
  return std::string(a) == b ? std::string(a) : std::string(a) + "-" + b;
}

std::string thermal_name(double tau_s) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "thermal (tau = %.0f s)", tau_s);
  return buf;
}

/// An effect not taken that the taken ones' columns reproduce: the parameter shift that moves
/// the fit from the taken explanation to it along the shared direction N = (n_T, n_C) of the
/// joint columns' null space (X_T n_T + X_C n_C = 0), for the chosen parameters the applied
/// ones only (what the result contains).
struct ConfoundedAlternative {
  const DisplacementEffect* effect = nullptr;
  std::string taken_name;  ///< the taken effect (group) that explains it instead
  Eigen::VectorXd shift_taken, shift_candidate;          ///< z·n_T (applied only), z·n_C
  Eigen::VectorXd direction_taken, direction_candidate;  ///< n_T (applied only), n_C
  double shift_variance = 0;                             ///< var(z)
};

std::vector<ConfoundedAlternative> confounded_alternatives(
    const Eigen::MatrixXd& X, const Eigen::VectorXd& beta, const Eigen::MatrixXd& cov,
    const std::vector<bool>& applied, const std::vector<DisplacementEffect>& chosen,
    const DisplacementEffectLibrary& lib, const Eigen::VectorXd& wt, double tolerance) {
  std::vector<ConfoundedAlternative> out;
  const auto K = X.cols();
  for (const auto& e : lib.effects) {
    if (!e.identifiable) continue;
    if (std::any_of(chosen.begin(), chosen.end(),
                    [&](const DisplacementEffect& c) { return c.family == e.family; }))
      continue;
    const auto kc = e.residual_columns.cols();
    Eigen::MatrixXd Z(X.rows(), K + kc);
    Z << X, wt.asDiagonal() * e.residual_columns;
    Eigen::VectorXd scale(K + kc);
    for (Eigen::Index j = 0; j < K + kc; ++j) {
      const double n = Z.col(j).norm();
      scale(j) = n > 0 ? 1.0 / n : 0.0;
    }
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(Z * scale.asDiagonal(), Eigen::ComputeThinV);
    const Eigen::VectorXd& sv = svd.singularValues();
    for (Eigen::Index i = 0; i < sv.size(); ++i) {
      if (!(sv(i) < tolerance)) continue;
      const Eigen::VectorXd v = svd.matrixV().col(i);
      // Only a direction shared by the taken columns and the candidate's (a null direction of
      // the taken columns alone is their own business, already in cov as a pseudo-inverse).
      if (v.head(K).norm() < 0.1 || v.tail(kc).norm() < 0.1) continue;
      const Eigen::VectorXd N = scale.cwiseProduct(v);
      const Eigen::VectorXd nT = N.head(K);
      const double nn = nT.squaredNorm();
      // z: the shift along N that leaves no taken parameter along n_T (the candidate explains it).
      const double z = -nT.dot(beta) / nn;
      ConfoundedAlternative a;
      a.effect = &e;
      a.direction_taken = nT;
      for (Eigen::Index j = 0; j < K; ++j)
        if (!applied[static_cast<std::size_t>(j)]) a.direction_taken(j) = 0;
      a.direction_candidate = N.tail(kc);
      a.shift_taken = z * a.direction_taken;
      a.shift_candidate = z * a.direction_candidate;
      a.shift_variance = std::max(0.0, nT.dot(cov * nT)) / (nn * nn);
      // Name the taken parameters the direction runs through.
      Eigen::Index c0 = 0, best = 0;
      double best_w = -1;
      for (Eigen::Index j = 0; j < K; ++j)
        if (std::abs(nT(j)) / scale(j) > best_w) {
          best_w = std::abs(nT(j)) / scale(j);
          best = j;
        }
      for (const auto& c : chosen) {
        const auto k = c.residual_columns.cols();
        if (best < c0 + k) {
          a.taken_name = c.family + " (" + c.parameters[static_cast<std::size_t>(best - c0)] + ")";
          break;
        }
        c0 += k;
      }
      out.push_back(std::move(a));
    }
  }
  return out;
}

double shape_ms(const Eigen::VectorXd& v) {
  return (v.array() - v.mean()).square().mean();
}

/// Columns centred (the gauge: w's constant removed).
Eigen::MatrixXd centred(const Eigen::MatrixXd& d) {
  return d.rowwise() - d.colwise().mean();
}

/// Mean over the points of diag(D C Dᵀ).
double mean_var(const Eigen::MatrixXd& D, const Eigen::MatrixXd& C) {
  return D.rows() ? (D * C).cwiseProduct(D).rowwise().sum().mean() : 0.0;
}

/// The automatic roll/pitch decision re-taken with the effects the redundancy sees
/// (displacement_refine.hpp, "Rotation correction"): 1 = on.  *line: the decision and its figures.
int decide_rotation(
    const TwoAxisScan& scan, const TwoAxisOptions& separation, const TwoAxisResult& base,
    const std::vector<DisplacementEffect>& chosen, const DisplacementEffectLibrary& lib,
    const std::function<Eigen::MatrixXd(const std::vector<const DisplacementEffect*>&)>& columns,
    const Eigen::VectorXd& y, int dof0, std::string* line, double* rotation_bias_um2) {
  TwoAxisOptions on = separation;
  on.rotation = RotationCorrection::on;
  const TwoAxisResult sep_on = separate_two_axis(scan, on);
  // b̂ = m_w(on) − m_w(off) = −(m_wxe + m_wye), per point (column major as the effects' d_w).
  const Eigen::MatrixXd b_grid = -(sep_on.m_wxe_um + sep_on.m_wye_um);
  const Eigen::VectorXd b_hat = Eigen::Map<const Eigen::VectorXd>(b_grid.data(), b_grid.size());
  const double noise_on = base.predicted_rms_on_um * base.predicted_rms_on_um;
  const double noise_off = std::max(0.0, base.predicted_rms_off_um * base.predicted_rms_off_um -
                                             base.rotation_bias_um * base.rotation_bias_um);
  const double u_b2 = base.rotation_terms_noise_um * base.rotation_terms_noise_um;

  // The explanations of the residual: the effects taken; those with one identifiable family not
  // taken added (thermal: every τ of the library's grid); and a taken thermal drift at every τ of
  // the grid (τ is poorly determined when the drift settles within a scan, and what the drift
  // puts into b̂ changes with it: seed 1607 of the diagonal case, τ̂ 216 s, 120-400 s not
  // rejected, the truth 374 s).  The first n_taken effects are corrected by the refine.
  struct Explanation {
    std::vector<const DisplacementEffect*> fx;
    std::size_t n_taken = 0;
  };
  std::vector<const DisplacementEffect*> taken;
  for (const auto& e : chosen)
    taken.push_back(&e);
  std::vector<Explanation> explanations = {{taken, taken.size()}};
  std::vector<std::string> families;
  for (const auto& e : lib.effects)
    if (e.identifiable && std::find(families.begin(), families.end(), e.family) == families.end())
      families.push_back(e.family);
  for (std::size_t t = 0; t < taken.size(); ++t)
    if (taken[t]->family == "thermal")
      for (const auto& e : lib.effects)
        if (e.family == "thermal" && e.identifiable) {
          auto fx = taken;
          fx[t] = &e;
          explanations.push_back({fx, fx.size()});
        }
  for (const auto& f : families) {
    if (std::any_of(chosen.begin(), chosen.end(),
                    [&](const DisplacementEffect& c) { return c.family == f; }))
      continue;
    for (const auto& e : lib.effects) {
      if (e.family != f || !e.identifiable) continue;
      auto fx = taken;
      fx.push_back(&e);
      explanations.push_back({fx, taken.size()});
    }
  }

  // Per explanation: its Akaike criterion (χ² of the whitened residual + 2 parameters, a
  // thermal τ counted as one more, as the selection ranks them) and its predicted errors.
  struct Explained {
    double aic = 0, e_on = 0, e_off = 0, rotation = 0, artefacts = 0, w = 0;
    double left[2] = {0, 0};  ///< mean square an effect not taken leaves in w, off and on
    std::string name;
  };
  std::vector<Explained> ex;
  const Eigen::Index N = b_hat.size();
  for (const auto& [fx, n_taken] : explanations) {
    // E_on = noise + what the artefacts do to w with Eqs. (22)-(27); E_off = noise + what they do
    // without + the share of b̂ they do not explain (taken to be a rotation).  The effects taken
    // are corrected by the refine (their fit's variance); an effect not taken is left in the
    // readings: its squared shape, estimated without its noise (D q̂ minus diag(D C Dᵀ)).
    Explained x;
    double B[2] = {0, 0};
    x.rotation = base.rotation_bias_um * base.rotation_bias_um;
    Eigen::Index K = 0;
    for (const auto* e : fx)
      K += e->residual_columns.cols();
    const detail::LsFit fit = detail::least_squares(columns(fx), y);
    x.aic = fit.rss + 2.0 * static_cast<double>(K);
    for (const auto* e : fx)  // τ chosen from the grid: one parameter more
      if (e->family == "thermal" &&
          std::find(e->parameters.begin(), e->parameters.end(), "dtau_s") == e->parameters.end())
        x.aic += 2.0;
    if (K > 0) {
      const Eigen::MatrixXd X = columns(fx);
      const double scale = fit.rss / std::max(1.0, static_cast<double>(dof0 - K));
      const Eigen::MatrixXd C =
          scale * (X.transpose() * X).completeOrthogonalDecomposition().pseudoInverse();
      Eigen::Index Kt = 0;
      for (std::size_t i = 0; i < n_taken; ++i)
        Kt += fx[i]->residual_columns.cols();
      Eigen::MatrixXd D[2];
      for (int r = 0; r < 2; ++r) {
        D[r].resize(N, K);
        Eigen::Index c = 0;
        for (const auto* e : fx) {
          D[r].middleCols(c, e->d_w[r].cols()) = centred(e->d_w[r]);
          c += e->d_w[r].cols();
        }
        B[r] = mean_var(D[r].leftCols(Kt), C.topLeftCorner(Kt, Kt));
        if (K > Kt) {
          const Eigen::MatrixXd Dc = D[r].rightCols(K - Kt);
          x.left[r] = std::max(0.0, shape_ms(Dc * fit.beta.tail(K - Kt)) -
                                        mean_var(Dc, C.bottomRightCorner(K - Kt, K - Kt)));
          B[r] += x.left[r];
        }
      }
      // b of the artefacts: m_w(on) − m_w(off) of their readings = d_w[1] − d_w[0].
      const Eigen::MatrixXd G = D[1] - D[0];
      x.artefacts = shape_ms(G * fit.beta);
      x.rotation = std::max(0.0, shape_ms(b_hat - G * fit.beta) - u_b2 - mean_var(G, C));
    }
    x.e_on = noise_on + B[1];
    x.e_off = noise_off + B[0] + x.rotation;
    for (const auto* e : fx)
      x.name += (x.name.empty() ? "" : " + ") + e->name;
    if (x.name.empty()) x.name = "noise alone";
    ex.push_back(x);
  }
  // Averaged over the explanations with Akaike weights (exp(−ΔAIC/2)): an effect too weak for
  // the selection's F-test still counts by how much better it fits (seed 1615 of the diagonal
  // case: a thermal drift of sensors 3-4, ΔAIC −9, moves w by 3.4 um with Eqs. 22-27, 0.2 without).
  double aic0 = std::numeric_limits<double>::infinity(), wsum = 0;
  for (const auto& x : ex)
    aic0 = std::min(aic0, x.aic);
  Explained avg;
  const Explained* best = &ex.front();
  for (auto& x : ex) {
    x.w = std::exp(-0.5 * (x.aic - aic0));
    wsum += x.w;
    if (x.w > best->w) best = &x;
  }
  for (const auto& x : ex) {
    avg.e_on += x.w / wsum * x.e_on;
    avg.e_off += x.w / wsum * x.e_off;
    avg.rotation += x.w / wsum * x.rotation;
    avg.artefacts += x.w / wsum * x.artefacts;
    for (int r = 0; r < 2; ++r)
      avg.left[r] += x.w / wsum * x.left[r];
  }
  // On only when the average says so and so does every explanation the data do not reject
  // against the likeliest (relative likelihood exp(−ΔAIC/2) >= 0.05): a sensor artefact taken for
  // a rotation is multiplied by the lever ratio, a rotation taken for an artefact is not.
  bool rotation_on = avg.e_on < avg.e_off;
  for (const auto& x : ex)
    if (x.w >= 0.05) rotation_on = rotation_on && x.e_on < x.e_off;
  // What the chosen branch's prediction holds beyond the separation's noise and the taken
  // effects' fit (which the refined u has): the effects not taken, and off the rotation share.
  if (rotation_bias_um2)
    *rotation_bias_um2 = rotation_on ? best->left[1] : best->left[0] + best->rotation;
  char buf[520];
  std::snprintf(buf, sizeof buf,
                "rotation correction %s (auto, re-taken with the effects the redundancy sees; the "
                "separation's was %s): rotation terms' shape %.3g um (noise %.3g um), of it %.3g "
                "um sensor artefacts and %.3g um rotation (averaged over the explanations, "
                "Akaike weights; likeliest %s, %.2f); predicted rms error of w's shape %.3g um "
                "with Eqs. (22)-(27), %.3g um without%s",
                rotation_on ? "on" : "off", base.rotation_corrected ? "on" : "off",
                std::sqrt(shape_ms(b_hat)), std::sqrt(u_b2), std::sqrt(avg.artefacts),
                std::sqrt(avg.rotation), best->name.c_str(), best->w / wsum, std::sqrt(avg.e_on),
                std::sqrt(avg.e_off), rotation_on ? "" : " (the rotation share carried in u)");
  *line = buf;
  return rotation_on ? 1 : 0;
}

}  // namespace

bool DisplacementRefineOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(alpha > 0 && alpha < 1))
    return fail("alpha = " + std::to_string(alpha) + ": not in (0, 1)");
  if (thermal_tau_scans.empty()) return fail("thermal_tau_scans is empty");
  for (const double t : thermal_tau_scans)
    if (!(std::isfinite(t) && t > 0))
      return fail("thermal_tau_scans has " + std::to_string(t) + ": must be > 0");
  if (!(identifiable_tolerance > 0 && identifiable_tolerance < 1))
    return fail("identifiable_tolerance = " + std::to_string(identifiable_tolerance) +
                ": not in (0, 1)");
  if (!(poorly_determined_ratio > 1))
    return fail("poorly_determined_ratio = " + std::to_string(poorly_determined_ratio) +
                ": must be > 1");
  std::string sub;
  if (!decision.is_valid(&sub)) return fail("decision." + sub);
  return true;
}

DisplacementDisturbance DisplacementEffect::unit(Eigen::Index k) const {
  DisplacementDisturbance d;
  const auto s = static_cast<std::size_t>(k);
  if (k >= 5) return d;  // thermal's dtau_s: not a unit disturbance (see refine_two_axis)
  if (family == "drift") d.drift_um_per_s[s] = 1.0;
  if (family == "thermal") {
    d.thermal_um[s] = 1.0;
    d.thermal_tau_s = tau_s;
  }
  if (family == "tilt") (k == 0 ? d.tilt_x_urad : d.tilt_y_urad) = 1.0;
  return d;
}

Eigen::VectorXd displacement_redundancy_residual(const TwoAxisScan& scan) {
  Eigen::MatrixXd d = scan_differences(scan);
  project(d, scan.s1_1_um.rows(), scan.s1_1_um.cols());
  return d.col(0);
}

DisplacementEffectLibrary make_displacement_effect_library(const Eigen::VectorXd& x_mm,
                                                           const Eigen::VectorXd& y_mm,
                                                           bool s0_repeat,
                                                           const TwoAxisScanOrder& order,
                                                           const TwoAxisOptions& separation,
                                                           const DisplacementRefineOptions& o) {
  std::string why;
  if (!o.is_valid(&why)) throw std::invalid_argument("displacement refine options: " + why);
  if (!order.is_valid(&why)) throw std::invalid_argument(why);
  if (!separation.is_valid(&why))
    throw std::invalid_argument("displacement refine: separation options: " + why);
  DisplacementEffectLibrary lib;
  lib.nx = static_cast<int>(x_mm.size());
  lib.ny = static_cast<int>(y_mm.size());
  lib.s0_repeat = s0_repeat;
  lib.order = order;
  const double scan_s = lib.nx * lib.ny * order.sample_period_s;

  std::vector<DisplacementEffect> fx;
  const std::vector<std::string> sensors = {"0", "1", "2", "3", "4"};
  {
    DisplacementEffect e;
    e.family = e.name = "drift";
    for (const auto& s : sensors)
      e.parameters.push_back("v" + s + "_um_per_s");
    e.groups = kSensorGroups;
    fx.push_back(e);
  }
  for (const double m : o.thermal_tau_scans) {
    DisplacementEffect e;
    e.family = "thermal";
    e.tau_s = m * scan_s;
    e.name = thermal_name(e.tau_s);
    for (const auto& s : sensors)
      e.parameters.push_back("a" + s + "_um");
    e.groups = kSensorGroups;
    fx.push_back(e);
  }
  {
    DisplacementEffect e;
    e.family = e.name = "tilt";
    e.parameters = {"tilt_x_urad", "tilt_y_urad"};
    e.groups = {{0, 1}};
    fx.push_back(e);
  }

  const TwoAxisScan zero = zero_scan(x_mm, y_mm, s0_repeat);
  for (auto& e : fx)
    complete_effect(e, zero, order, separation, o.identifiable_tolerance);
  // Families none of whose variants the plan identifies, said once.
  for (const auto& e : fx) {
    bool any = false, first = true;
    for (const auto& f : fx)
      if (f.family == e.family) {
        any = any || f.identifiable;
        if (&f != &e && &f < &e) first = false;
      }
    if (!any && first) {
      char buf[64];
      std::snprintf(buf, sizeof buf, " (relative singular value %.1e)", e.relative_singular_value);
      lib.not_identifiable.push_back(e.family + ": not identifiable from this plan" + buf + ": " +
                                     family_hint(e.family, s0_repeat));
    }
  }
  // Identifiable, but one pair of sensors' correction poorly determined beside the other pair's
  // (group_u_w_per_sigma, from the plan alone): on a raster scan 1 a column, what sensors 3-4
  // compare, is read within n_x samples, so their drift shows only through its fast part (file
  // comment; thermal of 3-4 halved 1/6/4 of 20 against 15/16/16 for 1-2).  Said once per family
  // and pair, with the time constants where it holds, so a user knows why that pair's correction
  // is rarely applied on this plan and which plan determines it.
  for (std::size_t a = 0; a < fx.size(); ++a) {
    const std::string& family = fx[a].family;
    bool first = true;
    for (std::size_t b = 0; b < a; ++b)
      first = first && fx[b].family != family;
    if (!first) continue;
    for (std::size_t g = 1; g < fx[a].groups.size(); ++g) {
      double lo = 1e300, hi = 0, other_lo = 1e300, other_hi = 0, tau_lo = 1e300, tau_hi = 0;
      for (const auto& e : fx) {
        if (e.family != family || e.group_u_w_per_sigma.size() != e.groups.size()) continue;
        double best_other = 1e300;
        for (std::size_t h = 1; h < e.groups.size(); ++h)
          if (h != g) best_other = std::min(best_other, e.group_u_w_per_sigma[h]);
        const double u = e.group_u_w_per_sigma[g];
        if (!(best_other < 1e300) || !(u > o.poorly_determined_ratio * best_other)) continue;
        lo = std::min(lo, u);
        hi = std::max(hi, u);
        other_lo = std::min(other_lo, best_other);
        other_hi = std::max(other_hi, best_other);
        tau_lo = std::min(tau_lo, e.tau_s);
        tau_hi = std::max(tau_hi, e.tau_s);
      }
      if (!(hi > 0)) continue;
      char buf[320];
      const std::string tau =
          family == "thermal" ? " at tau " + format_range(tau_lo, tau_hi, "%.0f") + " s" : "";
      std::snprintf(buf, sizeof buf,
                    "%s of %s: poorly determined on this plan (its correction adds %s um to "
                    "u(w) per um of reading noise%s, the other pair's %s): rarely worth applying; ",
                    family.c_str(), group_name(fx[a].groups[g]).c_str(),
                    format_range(lo, hi, "%.3g").c_str(), tau.c_str(),
                    format_range(other_lo, other_hi, "%.3g").c_str());
      std::string line = buf;
      line += g == 2 && !order.diagonal_scan1
                  ? "scan 1 along diagonals reads every column over the whole scan and determines "
                    "it as well as sensors 1-2's"
                  : "no plan of this library determines it better";
      lib.not_identifiable.push_back(line);
    }
  }
  lib.not_identifiable.push_back(
      "traverse error and yaw between the scans: not identifiable by two scans (a function of "
      "the piece's coordinate alone, absorbed by r); the traverse's u is in the separation's");
  lib.effects = std::move(fx);
  return lib;
}

bool DisplacementRefineResult::applied_any() const {
  for (const auto& s : steps)
    if (s.applied) return true;
  return false;
}

std::string DisplacementRefineResult::brief_report() const {
  std::ostringstream os;
  os << "displacement refine: " << steps.size() << " effect(s) taken, "
     << (applied_any() ? "corrections applied" : "nothing applied")
     << "; residual variance over sigma^2 after the fit " << sigma_scale << "\n";
  for (const auto& s : steps)
    os << "  " << s.line << " (F = " << s.F << ", p = " << s.p_value << ")\n";
  for (const auto& n : not_identifiable)
    os << "  " << n << "\n";
  return os.str();
}

DisplacementRefineResult refine_two_axis(const TwoAxisScan& scan, const TwoAxisOptions& separation,
                                         const DisplacementEffectLibrary& lib,
                                         const DisplacementRefineOptions& o) {
  std::string why;
  if (!o.is_valid(&why)) throw std::invalid_argument("displacement refine options: " + why);
  if (separation.solver != TwoAxisSolver::joint)
    throw std::invalid_argument(
        "displacement refine: needs the joint solver (the row-by-row path states no uncertainty)");
  if (scan.x_mm.size() != lib.nx || scan.y_mm.size() != lib.ny ||
      (scan.s0_2_um.size() != 0) != lib.s0_repeat)
    throw std::invalid_argument(
        "displacement refine: the scan's grid or sensor-0 repeat differs from the library's");
  DisplacementRefineResult out;
  out.not_identifiable = lib.not_identifiable;
  out.base = separate_two_axis(scan, separation);
  int rot = out.base.rotation_corrected ? 1 : 0;  // re-taken below when automatic
  TwoAxisOptions fixed = separation;

  // Whitened residual rows: a scan difference has variance 2σ² of its sensor kind.
  const Eigen::Index N = static_cast<Eigen::Index>(lib.nx) * lib.ny;
  const Eigen::VectorXd res = displacement_redundancy_residual(scan);
  Eigen::VectorXd wt(res.size());
  const double se = out.base.sigma_reference_um, s0 = out.base.sigma_workpiece_um;
  if (!(se > 0) || (lib.s0_repeat && !(s0 > 0)))
    throw std::invalid_argument("displacement refine: the separation's sigma is not positive");
  wt.head(4 * N).setConstant(1.0 / (std::sqrt(2.0) * se));
  if (lib.s0_repeat) wt.tail(N).setConstant(1.0 / (std::sqrt(2.0) * s0));
  const Eigen::VectorXd y = wt.cwiseProduct(res);
  int dof0 = 2 * lib.nx * (lib.ny - 1) + 2 * lib.ny * (lib.nx - 1);
  if (lib.s0_repeat) dof0 += static_cast<int>(N) - 1;
  auto columns = [&](const std::vector<const DisplacementEffect*>& fx) {
    Eigen::Index k = 0;
    for (const auto* e : fx)
      k += e->residual_columns.cols();
    Eigen::MatrixXd X(y.size(), k);
    k = 0;
    for (const auto* e : fx) {
      X.middleCols(k, e->residual_columns.cols()) = wt.asDiagonal() * e->residual_columns;
      k += e->residual_columns.cols();
    }
    return X;
  };
  auto pointers = [](const std::vector<DisplacementEffect>& v) {
    std::vector<const DisplacementEffect*> p;
    for (const auto& e : v)
      p.push_back(&e);
    return p;
  };
  const TwoAxisScan zero = zero_scan(scan.x_mm, scan.y_mm, lib.s0_repeat);

  // Forward selection, one variant per family (displacement_effect_selection.hpp).
  std::vector<detail::SelectionCandidate> sc;
  for (const auto& e : lib.effects)
    sc.push_back({e.family, e.identifiable, e.family == "thermal"});
  auto columns_of = [&](const std::vector<std::size_t>& idx) {
    std::vector<const DisplacementEffect*> fx;
    for (const auto i : idx)
      fx.push_back(&lib.effects[i]);
    return columns(fx);
  };
  std::vector<DisplacementEffect> chosen;
  std::vector<double> taken_F, taken_p;
  for (const auto& sel : detail::forward_select(sc, columns_of, y, dof0, o.alpha)) {
    chosen.push_back(lib.effects[sel.index]);
    taken_F.push_back(sel.F);
    taken_p.push_back(sel.p_value);
  }

  // The thermal time constant between the grid's neighbours of the chosen variant: golden
  // section on log τ of the residual sum of squares with every chosen effect in the fit.
  for (auto& e : chosen) {
    if (e.family != "thermal") continue;
    double lo = e.tau_s, hi = e.tau_s;
    for (const auto& f : lib.effects)
      if (f.family == "thermal") {
        if (f.tau_s < e.tau_s && (lo == e.tau_s || f.tau_s > lo)) lo = f.tau_s;
        if (f.tau_s > e.tau_s && (hi == e.tau_s || f.tau_s < hi)) hi = f.tau_s;
      }
    if (lo == e.tau_s) lo = e.tau_s / 1.5;
    if (hi == e.tau_s) hi = e.tau_s * 1.5;
    DisplacementEffect trial = e;
    auto rss_at = [&](double log_tau) {
      trial.tau_s = std::exp(log_tau);
      trial.residual_columns = residual_columns(trial, zero, lib.order);
      auto fx = pointers(chosen);
      for (auto*& q : fx)
        if (q == &e) q = &trial;
      return detail::least_squares(columns(fx), y).rss;
    };
    // 14 golden-section steps: the bracket shrinks to 0.3 % of its width (τ to ~1e-3 relative).
    e.tau_s = std::exp(golden_section_minimum(rss_at, std::log(lo), std::log(hi), 0.0, 14));
    e.name = thermal_name(e.tau_s);
    complete_effect(e, zero, lib.order, separation, o.identifiable_tolerance);
    // τ is estimated too, and the amplitudes trade with it (a long τ's slope is what no scan
    // difference sees): a Gauss–Newton column dtau_s, Σ â_k ∂E_k/∂τ by central differences, in
    // the fit and in every group's decision, so that the decision carries τ's uncertainty.
    const detail::LsFit f0 = detail::least_squares(columns(pointers(chosen)), y);
    Eigen::Index off = 0;
    for (const auto& other : chosen) {
      if (&other == &e) break;
      off += other.residual_columns.cols();
    }
    DisplacementDisturbance hi_d, lo_d;
    const double h = 1e-3 * e.tau_s;
    for (int k = 0; k < 5; ++k)
      hi_d.thermal_um[static_cast<std::size_t>(k)] = lo_d.thermal_um[static_cast<std::size_t>(k)] =
          f0.beta(off + k);
    hi_d.thermal_tau_s = e.tau_s + h;
    lo_d.thermal_tau_s = e.tau_s - h;
    TwoAxisScan s_hi = zero, s_lo = zero;
    add_disturbance(s_hi, hi_d, lib.order);
    add_disturbance(s_lo, lo_d, lib.order);
    Eigen::VectorXd col = (scan_differences(s_hi) - scan_differences(s_lo)) / (2 * h);
    project(col, lib.nx, lib.ny);
    const auto k = e.residual_columns.cols();
    e.residual_columns.conservativeResize(Eigen::NoChange, k + 1);
    e.residual_columns.col(k) = col;
    for (int r = 0; r < 2; ++r) {
      TwoAxisOptions so = separation;
      so.rotation = r ? RotationCorrection::on : RotationCorrection::off;
      so.displacement_sigma_mm = 0;
      const TwoAxisResult sh = separate_two_axis(s_hi, so), sl = separate_two_axis(s_lo, so);
      e.d_w[r].conservativeResize(Eigen::NoChange, k + 1);
      e.d_m_w[r].conservativeResize(Eigen::NoChange, k + 1);
      e.d_w[r].col(k) = -flatten(sh.w_um - sl.w_um) / (2 * h);
      e.d_m_w[r].col(k) = -flatten(sh.m_w_um - sl.m_w_um) / (2 * h);
    }
    e.parameters.push_back("dtau_s");
    for (auto& grp : e.groups)
      grp.push_back(static_cast<int>(k));
  }

  // The automatic roll/pitch decision re-taken with what the redundancy sees (header).
  std::string rotation_line;
  double rotation_bias_um2 = 0;  // what auto's branch leaves in w beyond the refined u (below)
  if (separation.rotation == RotationCorrection::automatic) {
    rot = decide_rotation(scan, separation, out.base, chosen, lib, columns, y, dof0, &rotation_line,
                          &rotation_bias_um2);
    out.not_identifiable.push_back(rotation_line);
  }
  fixed.rotation = rot ? RotationCorrection::on : RotationCorrection::off;
  // The separation in the decided rotation (the measured readings'), for the decisions' u.
  const TwoAxisResult base_r =
      rot == (out.base.rotation_corrected ? 1 : 0) ? out.base : separate_two_axis(scan, fixed);
  out.refined = base_r;
  if (!rotation_line.empty()) {
    out.refined.rotation_requested = RotationCorrection::automatic;
    out.refined.rotation_note = rotation_line;
  }
  // What auto's branch leaves in w beyond the separation's noise and the taken effects' fit: off,
  // the share of the rotation terms no artefact explains; either, what effects too weak to be
  // taken do to w.  Carried in u, the same at every point (an estimate of its mean square).
  auto carry_rotation = [&](TwoAxisResult& r) {
    if (!(rotation_bias_um2 > 0)) return;
    r.u_w_um = (r.u_w_um.array().square() + rotation_bias_um2).sqrt();
    r.u_m_w_um = (r.u_m_w_um.array().square() + rotation_bias_um2).sqrt();
  };
  if (chosen.empty()) {
    // Nothing taken: the refined result is the separation (rotation as decided above).
    carry_rotation(out.refined);
    return out;
  }
  const Eigen::MatrixXd X = columns(pointers(chosen));
  const detail::LsFit fit = detail::least_squares(X, y);
  const auto K = X.cols();
  // The values applied: the fit at τ̂ without the dtau_s column (a Gauss–Newton direction for the
  // decision's covariance, not a step: a τ̂ at the edge of its bracket can leave dtau_s far from
  // 0, and amplitudes conditioned on it would not match the readings corrected at τ̂).
  Eigen::VectorXd applied_value = fit.beta;
  double rss_applied = fit.rss;  // of the fit the applied values come from
  {
    std::vector<Eigen::Index> keep;
    Eigen::Index c = 0;
    for (const auto& e : chosen)
      for (const auto& nm : e.parameters) {
        if (nm != "dtau_s") keep.push_back(c);
        ++c;
      }
    if (static_cast<Eigen::Index>(keep.size()) < K) {
      Eigen::MatrixXd X0(X.rows(), static_cast<Eigen::Index>(keep.size()));
      for (std::size_t j = 0; j < keep.size(); ++j)
        X0.col(static_cast<Eigen::Index>(j)) = X.col(keep[j]);
      const detail::LsFit f0 = detail::least_squares(X0, y);
      rss_applied = f0.rss;
      applied_value.setZero();
      for (std::size_t j = 0; j < keep.size(); ++j)
        applied_value(keep[j]) = f0.beta(static_cast<Eigen::Index>(j));
    }
  }
  out.sigma_scale = fit.rss / (dof0 - K);
  const Eigen::MatrixXd cov =
      out.sigma_scale * (X.transpose() * X).completeOrthogonalDecomposition().pseudoInverse();

  const Eigen::VectorXd u_w0 = flatten(base_r.u_w_um), u_m0 = flatten(base_r.u_m_w_um);
  Eigen::MatrixXd Dw(N, K), Dm(N, K);
  std::vector<bool> applied(static_cast<std::size_t>(K), false);
  DisplacementDisturbance correction;
  Eigen::Index c0 = 0;
  for (std::size_t t = 0; t < chosen.size(); ++t) {
    const auto& e = chosen[t];
    const auto k = e.residual_columns.cols();
    Dw.middleCols(c0, k) = e.d_w[rot];
    Dm.middleCols(c0, k) = e.d_m_w[rot];
    // Each group of parameters decided on its own block (a reference piece read along the
    // raster's slow axis may be well determined while the other is not).
    for (const auto& grp : e.groups) {
      const auto kg = static_cast<Eigen::Index>(grp.size());
      Eigen::MatrixXd gw(N, kg), gm(N, kg), ck(kg, kg);
      DisplacementRefineStep st;
      st.effect = e.name + (e.groups.size() > 1 ? ", " + group_name(grp) : std::string());
      st.value.resize(kg);
      for (Eigen::Index a = 0; a < kg; ++a) {
        const Eigen::Index ia = grp[static_cast<std::size_t>(a)];
        st.names.push_back(e.parameters[static_cast<std::size_t>(ia)]);
        st.value(a) = fit.beta(c0 + ia);
        // The gauge (the constant of w and m_w) removed for the decision.
        gw.col(a) = e.d_w[rot].col(ia).array() - e.d_w[rot].col(ia).mean();
        gm.col(a) = e.d_m_w[rot].col(ia).array() - e.d_m_w[rot].col(ia).mean();
        for (Eigen::Index b = 0; b < kg; ++b)
          ck(a, b) = cov(c0 + ia, c0 + grp[static_cast<std::size_t>(b)]);
      }
      st.u = ck.diagonal().cwiseMax(0.0).cwiseSqrt();
      st.F = taken_F[t];
      st.p_value = taken_p[t];
      st.decision =
          decide_step(st.value, ck, {{"w", "um", gw, u_w0}, {"m_w", "um", gm, u_m0}}, o.decision);
      st.applied = st.decision.apply;
      st.line = describe_decision(st.effect, st.names, st.value, st.u, st.decision);
      if (st.applied) {
        for (const int ia : grp) {
          applied[static_cast<std::size_t>(c0 + ia)] = true;
          if (e.family == "thermal" && ia >= 5) continue;  // dtau_s: set with τ below
          const DisplacementDisturbance u = e.unit(ia);
          const double v = -applied_value(c0 + ia);
          for (int s = 0; s < 5; ++s) {
            correction.drift_um_per_s[s] += v * u.drift_um_per_s[s];
            correction.thermal_um[s] += v * u.thermal_um[s];
          }
          correction.tilt_x_urad += v * u.tilt_x_urad;
          correction.tilt_y_urad += v * u.tilt_y_urad;
          if (e.family == "thermal")
            correction.thermal_tau_s = e.tau_s;  // τ̂ (dtau_s is ≈ 0 there; a linearisation)
        }
      }
      out.steps.push_back(std::move(st));
    }
    c0 += k;
  }
  if (out.applied_any()) {
    TwoAxisScan corrected = scan;
    add_disturbance(corrected, correction, lib.order);
    out.refined = separate_two_axis(corrected, fixed);
    if (!rotation_line.empty()) {
      out.refined.rotation_requested = RotationCorrection::automatic;
      out.refined.rotation_note = rotation_line;
    }
  }
  // The refined u: the separation's with the applied parameters' covariance and the bias of the
  // ones left out (step_decision.hpp), and for those also their fitted size's own scatter.  An
  // effect is left out because it is poorly determined, so its fitted size D·p̂ may be small where
  // the true D·p is not (p̂ − p has covariance C): the bias is bounded by (D p̂)² + diag(D C Dᵀ),
  // not by (D p̂)² alone (with it alone, the cells where an effect was detected and not applied
  // covered 0.64-0.93 within 2u).
  std::vector<bool> left_out(applied.size());
  for (std::size_t j = 0; j < applied.size(); ++j)
    left_out[j] = !applied[j];
  const Eigen::VectorXd no_bias = Eigen::VectorXd::Zero(K);
  auto widened = [&](const Eigen::MatrixXd& u_sep, const Eigen::MatrixXd& D) {
    const Eigen::VectorXd u = refined_uncertainty(flatten(u_sep), D, cov, fit.beta, applied);
    // refined_uncertainty with the roles swapped adds diag(D_L C_LL D_Lᵀ) (no bias term).
    return refined_uncertainty(u, D, cov, no_bias, left_out);
  };
  Eigen::VectorXd uw = widened(out.refined.u_w_um, Dw);
  Eigen::VectorXd um = widened(out.refined.u_m_w_um, Dm);
  // τ is not a linear parameter: the Gauss–Newton column carries its scatter only near τ̂, and
  // a first-order drift that settles within a scan leaves the residual nearly flat in τ over a
  // wide range, where the amplitudes (and what they do to w) change fast.  Every τ of the
  // library's grid that the data do not reject (profile likelihood, 95 %: the residual sum of
  // squares within χ²₁ = 3.84 σ̂² of the one at τ̂) is refitted with the other chosen effects,
  // and the largest change of the thermal correction's w over that set is carried in u.
  {
    Eigen::Index off = 0;
    for (std::size_t t = 0; t < chosen.size(); ++t) {
      const auto& e = chosen[t];
      if (e.family != "thermal") {
        off += e.residual_columns.cols();
        continue;
      }
      const Eigen::VectorXd w_hat = e.d_w[rot].leftCols(5) * applied_value.segment(off, 5);
      const Eigen::VectorXd m_hat = e.d_m_w[rot].leftCols(5) * applied_value.segment(off, 5);
      Eigen::VectorXd spread_w = Eigen::VectorXd::Zero(N), spread_m = Eigen::VectorXd::Zero(N);
      double tau_lo = e.tau_s, tau_hi = e.tau_s;
      for (const auto& f : lib.effects) {
        if (f.family != "thermal") continue;
        auto fx = pointers(chosen);
        fx[t] = &f;
        const detail::LsFit ff = detail::least_squares(columns(fx), y);
        if (ff.rss - rss_applied > 3.84 * out.sigma_scale) continue;
        tau_lo = std::min(tau_lo, f.tau_s);
        tau_hi = std::max(tau_hi, f.tau_s);
        spread_w = spread_w.cwiseMax(
            (f.d_w[rot].leftCols(5) * ff.beta.segment(off, 5) - w_hat).cwiseAbs());
        spread_m = spread_m.cwiseMax(
            (f.d_m_w[rot].leftCols(5) * ff.beta.segment(off, 5) - m_hat).cwiseAbs());
      }
      uw = (uw.array().square() + spread_w.array().square()).sqrt();
      um = (um.array().square() + spread_m.array().square()).sqrt();
      char buf[240];
      std::snprintf(buf, sizeof buf,
                    "thermal tau %.0f s fitted; %.0f-%.0f s not rejected by the data (95 %%): its "
                    "w differs by up to %.3g um rms over that range (carried in u)",
                    e.tau_s, tau_lo, tau_hi, std::sqrt(spread_w.array().square().mean()));
      out.not_identifiable.push_back(buf);
      off += e.residual_columns.cols();
    }
  }
  // An effect not taken whose columns the taken ones reproduce exactly explains the same
  // residual: the selection kept one explanation, the data cannot choose.  Its w is carried in u.
  for (const auto& alt : confounded_alternatives(X, fit.beta, cov, applied, chosen, lib, wt,
                                                 o.identifiable_tolerance)) {
    const Eigen::VectorXd dw = Dw * alt.shift_taken + alt.effect->d_w[rot] * alt.shift_candidate;
    const Eigen::VectorXd dm = Dm * alt.shift_taken + alt.effect->d_m_w[rot] * alt.shift_candidate;
    const Eigen::VectorXd sw =
        Dw * alt.direction_taken + alt.effect->d_w[rot] * alt.direction_candidate;
    const Eigen::VectorXd sm =
        Dm * alt.direction_taken + alt.effect->d_m_w[rot] * alt.direction_candidate;
    uw = (uw.array().square() + dw.array().square() + alt.shift_variance * sw.array().square())
             .sqrt();
    um = (um.array().square() + dm.array().square() + alt.shift_variance * sm.array().square())
             .sqrt();
    char buf[320];
    std::snprintf(buf, sizeof buf,
                  "%s and %s: not separable on this plan (the data fit both alike); taken as %s, "
                  "as %s w would differ by %.3g um rms (carried in u)",
                  alt.taken_name.c_str(), alt.effect->family.c_str(), alt.taken_name.c_str(),
                  alt.effect->family.c_str(), std::sqrt(dw.array().square().mean()));
    out.not_identifiable.push_back(buf);
  }
  out.refined.u_w_um = Eigen::Map<const Eigen::MatrixXd>(uw.data(), lib.nx, lib.ny);
  out.refined.u_m_w_um = Eigen::Map<const Eigen::MatrixXd>(um.data(), lib.nx, lib.ny);
  carry_rotation(out.refined);
  return out;
}

}  // namespace errsep::core

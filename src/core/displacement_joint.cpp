#include "errsep/core/displacement_joint.hpp"

#include <chrono>
#include <cmath>
#include <stdexcept>

#include "errsep/core/model_effect.hpp"  // grid_derivative

namespace errsep::core {
namespace {

/// Where a track's unknowns sit in the joint system: every track's m first (n_a·n_b each, column
/// major), then every track's r(a_p … a_{n_a−1+p}).  With this order the natural ordering has no
/// fill beyond r(a_i)–r(a_{i+p}): eliminating m(a_i, b_j) couples only the two r it is read with.
struct TrackLayout {
  Eigen::Index na = 0, nb = 0, p = 1, m0 = 0, r0 = 0;
  Eigen::Index m(Eigen::Index i, Eigen::Index j) const { return m0 + j * na + i; }
  /// Index of r(a_k), or -1 for the gauge-fixed r(a_0 … a_{p−1}).
  Eigen::Index r(Eigen::Index k) const { return k < p ? -1 : r0 + k - p; }
};

}  // namespace

JointReferenceFit fit_reference_tracks(const std::vector<ReferenceTrackScan>& tracks,
                                       const std::vector<MotionFunctional>& functionals) {
  const auto t0 = std::chrono::steady_clock::now();
  if (tracks.empty()) throw std::invalid_argument("joint displacement fit: no reference track");
  std::vector<TrackLayout> lay(tracks.size());
  Eigen::Index unknowns = 0, observations = 0;
  for (std::size_t t = 0; t < tracks.size(); ++t) {
    const auto& tr = tracks[t];
    const std::string name = "joint displacement fit: track " + std::to_string(t);
    if (tr.scan2_um.rows() != tr.scan1_um.rows() || tr.scan2_um.cols() != tr.scan1_um.cols())
      throw std::invalid_argument(name + ": the two scans differ in size");
    if (tr.step < 1 || tr.scan1_um.rows() <= tr.step || tr.scan1_um.cols() < 1)
      throw std::invalid_argument(
          name + ": " + std::to_string(tr.scan1_um.rows()) +
          " samples along the piece do not reach beyond d/da = " + std::to_string(tr.step));
    if (!tr.scan1_um.allFinite() || !tr.scan2_um.allFinite())
      throw std::invalid_argument(name + ": non-finite reading");
    if (!(tr.spacing_mm > 0)) throw std::invalid_argument(name + ": spacing_mm must be > 0");
    lay[t].na = tr.scan1_um.rows();
    lay[t].nb = tr.scan1_um.cols();
    lay[t].p = tr.step;
    lay[t].m0 = unknowns;
    unknowns += lay[t].na * lay[t].nb;
    observations += 2 * lay[t].na * lay[t].nb;
  }
  for (auto& l : lay) {
    l.r0 = unknowns;
    unknowns += l.na;  // r(a_p … a_{n_a−1+p})
  }
  if (unknowns > std::numeric_limits<int>::max() / 2 ||
      observations > std::numeric_limits<int>::max() / 4)
    throw std::invalid_argument("joint displacement fit: grid too large for 32-bit indices");

  // Aᵀ in compressed columns, one column per reading (scan 1 then scan 2 of each point), two
  // entries each (m, then r when r is not the gauge's).
  Eigen::SparseMatrix<double> at(unknowns, observations);
  at.resizeNonZeros(2 * observations);
  int* outer = at.outerIndexPtr();
  int* inner = at.innerIndexPtr();
  double* val = at.valuePtr();
  Eigen::VectorXd b(observations);
  int nnz = 0;
  Eigen::Index col = 0;
  auto add_reading = [&](Eigen::Index m_idx, Eigen::Index r_idx, double value) {
    outer[col] = nnz;
    inner[nnz] = static_cast<int>(m_idx);
    val[nnz++] = 1.0;
    if (r_idx >= 0) {
      inner[nnz] = static_cast<int>(r_idx);
      val[nnz++] = 1.0;
    }
    b(col++) = value;
  };
  for (std::size_t t = 0; t < tracks.size(); ++t) {
    const auto& l = lay[t];
    for (Eigen::Index j = 0; j < l.nb; ++j)
      for (Eigen::Index i = 0; i < l.na; ++i) {
        add_reading(l.m(i, j), l.r(i), tracks[t].scan1_um(i, j));
        add_reading(l.m(i, j), l.r(i + l.p), tracks[t].scan2_um(i, j));
      }
  }
  outer[col] = nnz;
  at.data().resize(nnz);

  SparseLeastSquaresOptions so;
  so.natural_ordering = true;
  const SparseLeastSquares ls(at, so);
  if (ls.status() != SparseLeastSquaresStatus::success)
    throw std::runtime_error(std::string("joint displacement fit: ") + to_string(ls.status()) +
                             ": " + ls.message());
  const Eigen::VectorXd x = ls.solve(b);
  const Eigen::VectorXd zdiag = ls.inverse_diagonal();

  JointReferenceFit out;
  out.tracks.resize(tracks.size());
  Eigen::VectorXd rhs_d = Eigen::VectorXd::Zero(unknowns);  // Aᵀ·Δs per mm of δ, all tracks
  for (std::size_t t = 0; t < tracks.size(); ++t) {
    const auto& l = lay[t];
    auto& f = out.tracks[t];
    f.r_um = Eigen::VectorXd::Zero(l.na + l.p);
    f.var_r = Eigen::VectorXd::Zero(l.na + l.p);
    for (Eigen::Index k = l.p; k < l.na + l.p; ++k) {
      f.r_um(k) = x(l.r(k));
      f.var_r(k) = zdiag(l.r(k));
    }
    f.m_um.resize(l.na, l.nb);
    f.var_m.resize(l.na, l.nb);
    f.rss_um2 = 0;
    Eigen::VectorXd dr(f.r_um.size());  // r′ per mm from r̂ (central inside, one-sided at ends)
    for (Eigen::Index k = 0; k < dr.size(); ++k)
      dr(k) = grid_derivative(f.r_um, tracks[t].spacing_mm, k);
    for (Eigen::Index j = 0; j < l.nb; ++j)
      for (Eigen::Index i = 0; i < l.na; ++i) {
        const double m = x(l.m(i, j));
        f.m_um(i, j) = m;
        f.var_m(i, j) = zdiag(l.m(i, j));
        const double e1 = tracks[t].scan1_um(i, j) - f.r_um(i) - m;
        const double e2 = tracks[t].scan2_um(i, j) - f.r_um(i + l.p) - m;
        f.rss_um2 += e1 * e1 + e2 * e2;
        // Scan 2 reads r(a_i + d + δ): Δs = δ·r′(a_{i+p}) on the reading of m(a_i, b_j) and
        // r(a_{i+p}).
        rhs_d(l.m(i, j)) += dr(i + l.p);
        rhs_d(l.r(i + l.p)) += dr(i + l.p);
      }
    f.dof = static_cast<int>(l.na * (l.nb - 1));
  }
  // One solve for the traverse sensitivity of every track (the blocks share no unknown), then
  // one per requested functional (a column at a time: a 1000 x 1000 grid has 4·10⁶ unknowns).
  const Eigen::VectorXd sens = ls.solve_normal(rhs_d);
  for (std::size_t t = 0; t < tracks.size(); ++t) {
    const auto& l = lay[t];
    auto& f = out.tracks[t];
    f.dr_dd_um_per_mm = Eigen::VectorXd::Zero(l.na + l.p);
    for (Eigen::Index k = l.p; k < l.na + l.p; ++k)
      f.dr_dd_um_per_mm(k) = sens(l.r(k));
    f.dm_dd_um_per_mm.resize(l.na, l.nb);
    for (Eigen::Index j = 0; j < l.nb; ++j)
      for (Eigen::Index i = 0; i < l.na; ++i)
        f.dm_dd_um_per_mm(i, j) = sens(l.m(i, j));
  }
  for (std::size_t q = 0; q < functionals.size(); ++q) {
    const auto& g = functionals[q];
    rhs_d.setZero();
    for (std::size_t t = 0; t < tracks.size() && t < g.size(); ++t) {
      if (g[t].size() == 0) continue;
      const auto& l = lay[t];
      if (g[t].rows() != l.na || g[t].cols() != l.nb)
        throw std::invalid_argument("joint displacement fit: functional " + std::to_string(q) +
                                    " does not match track " + std::to_string(t));
      for (Eigen::Index j = 0; j < l.nb; ++j)
        for (Eigen::Index i = 0; i < l.na; ++i)
          rhs_d(l.m(i, j)) = g[t](i, j);
    }
    out.functional_var.push_back(rhs_d.dot(ls.solve_normal(rhs_d).col(0)));
  }
  out.stats = ls.stats();
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

OneAxisJointResult separate_displacement_joint(const Eigen::VectorXd& s1_1,
                                               const Eigen::VectorXd& s2_1,
                                               const Eigen::VectorXd& s2_2,
                                               const Eigen::VectorXd& s1_2,
                                               const DisplacementOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("displacement method: " + why);
  const Eigen::Index n = s2_1.size();
  if (s2_2.size() != n || s1_1.size() != n || (s1_2.size() != 0 && s1_2.size() != n))
    throw std::invalid_argument("displacement method: the scans differ in length (" +
                                std::to_string(s1_1.size()) + ", " + std::to_string(n) + ", " +
                                std::to_string(s2_2.size()) + ", " + std::to_string(s1_2.size()) +
                                ")");
  if (!s1_1.allFinite() || (s1_2.size() && !s1_2.allFinite()))
    throw std::invalid_argument("displacement method: non-finite workpiece reading");
  const int p = opts.step_ratio();
  ReferenceTrackScan track{s2_1, s2_2, p, opts.sample_interval_mm};
  const JointReferenceFit fit = fit_reference_tracks({track});
  const auto& f = fit.tracks.front();

  OneAxisJointResult out;
  auto& e = out.estimate;
  e.step_ratio = p;
  e.chains = p;
  e.r_um = f.r_um.head(n);
  e.m_um = f.m_um.col(0);
  // Chain offsets (p > 1) and r(x_1): moves along the gauge, which the data cannot see.
  Eigen::VectorXd shift = Eigen::VectorXd::Constant(n, opts.initial_um);
  if (p > 1 && opts.chain_join == ChainJoin::least_roughness) {
    const Eigen::VectorXd c = least_roughness_offsets(e.r_um, p);
    for (Eigen::Index k = 0; k < n; ++k)
      if (k % p) shift(k) += c(k % p - 1);
  }
  e.r_um += shift;
  e.m_um -= shift;
  const double n0 = s1_2.size() ? 2.0 : 1.0;
  const Eigen::VectorXd s1_mean = s1_2.size() ? Eigen::VectorXd(0.5 * (s1_1 + s1_2)) : s1_1;
  e.w_um = s1_mean - e.m_um;  // Eq. (1)
  out.gauge = p == 1 ? "r(x_1) = " + std::to_string(opts.initial_um) +
                           " um (Eq. 9): r, m and w are determined up to this constant"
                     : "r(x_1..x_p) of the " + std::to_string(p) + " chains of Eq. (9) set by " +
                           (opts.chain_join == ChainJoin::least_roughness
                                ? std::string("least roughness")
                                : std::string("the given initial value")) +
                           ": r, m and w are determined up to a pattern of period d; u is that "
                           "of the chains' first samples fixed";

  // σ of a reading.
  if (std::isfinite(opts.reading_sigma_um)) {
    out.sigma_um = opts.reading_sigma_um;
    out.sigma_source = "given";
  } else if (s1_2.size() && n > 1) {
    // Workpiece repeat: S1_2 − S1_1 = offset + noise of variance 2σ²; one offset fitted.
    const Eigen::VectorXd diff = s1_2 - s1_1;
    const double rss = (diff.array() - diff.mean()).square().sum();
    out.sigma_dof = static_cast<int>(n - 1);
    out.sigma_um = std::sqrt(rss / (2.0 * out.sigma_dof));
    out.sigma_source = "workpiece repeat (sensor 1 in both scans, dof " +
                       std::to_string(out.sigma_dof) +
                       "); the reference sensor taken as equally noisy";
  } else {
    out.sigma_source =
        "none: Eqs. (1)-(3) are exactly determined; record sensor 1 in scan 2 or give the "
        "reading sigma for an uncertainty";
    return out;
  }
  const double s2 = out.sigma_um * out.sigma_um;
  const double sd = opts.displacement_sigma_mm;
  out.u_r_um =
      (s2 * f.var_r.head(n).array() + (sd * f.dr_dd_um_per_mm.head(n).array()).square()).sqrt();
  out.u_m_um =
      (s2 * f.var_m.col(0).array() + (sd * f.dm_dd_um_per_mm.col(0).array()).square()).sqrt();
  out.u_w_um = (out.u_m_um.array().square() + s2 / n0).sqrt();
  return out;
}

}  // namespace errsep::core

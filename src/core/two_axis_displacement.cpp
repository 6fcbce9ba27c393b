#include "errsep/core/two_axis_displacement.hpp"

#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "errsep/core/displacement_joint.hpp"

namespace errsep::core {
namespace {

DisplacementOptions axis_options(double dx, double d, ChainJoin join) {
  DisplacementOptions o;
  o.sample_interval_mm = dx;
  o.displacement_mm = d;
  o.chain_join = join;
  return o;
}

/// Shifts a fitted track along its gauge so that its p chains join with least roughness
/// (ChainJoin::least_roughness, p > 1): r + c_{i mod p}, m − c_{i mod p}.
void join_chains(ReferenceTrackFit& f, int p) {
  const Eigen::Index na = f.m_um.rows();
  const Eigen::VectorXd c = least_roughness_offsets(f.r_um.head(na), p);
  for (Eigen::Index k = 0; k < f.r_um.size(); ++k)
    if (k % p) f.r_um(k) += c(k % p - 1);
  for (Eigen::Index i = 0; i < na; ++i)
    if (i % p) f.m_um.row(i).array() -= c(i % p - 1);
}

/// The paper's path: Eq. (9) on each row (sensors 1, 2) and column (3, 4), m from scan 1.
TwoAxisResult row_by_row(const TwoAxisScan& scan, const TwoAxisOptions& opts) {
  const Eigen::Index nx = scan.x_mm.size(), ny = scan.y_mm.size();
  const DisplacementOptions ox = axis_options(opts.dx_mm, opts.displacement_x_mm, opts.chain_join);
  const DisplacementOptions oy = axis_options(opts.dy_mm, opts.displacement_y_mm, opts.chain_join);
  TwoAxisResult res;
  res.solver = TwoAxisSolver::row_by_row;
  res.rotation_requested = opts.rotation;
  res.rotation_corrected = opts.rotation != RotationCorrection::off;
  if (opts.rotation == RotationCorrection::automatic)
    res.rotation_note = "automatic means on with the row-by-row solver (no covariance)";
  for (auto* m : {&res.r1x_um, &res.r2x_um, &res.r3y_um, &res.r4y_um, &res.m1x_um, &res.m2x_um,
                  &res.m3y_um, &res.m4y_um})
    m->resize(nx, ny);

  // Eqs. (11), (12), (16), (17): sensors 1, 2 along x on every row y_j.
  for (Eigen::Index j = 0; j < ny; ++j) {
    const auto r1 = separate_reference(scan.s1_1_um.col(j), scan.s1_2_um.col(j), ox);
    const auto r2 = separate_reference(scan.s2_1_um.col(j), scan.s2_2_um.col(j), ox);
    res.r1x_um.col(j) = r1.r_um;
    res.m1x_um.col(j) = r1.m_um;
    res.r2x_um.col(j) = r2.r_um;
    res.m2x_um.col(j) = r2.m_um;
  }
  // Eqs. (13), (14), (18), (19): sensors 3, 4 along y on every column x_i.
  for (Eigen::Index i = 0; i < nx; ++i) {
    const auto r3 =
        separate_reference(scan.s3_1_um.row(i).transpose(), scan.s3_2_um.row(i).transpose(), oy);
    const auto r4 =
        separate_reference(scan.s4_1_um.row(i).transpose(), scan.s4_2_um.row(i).transpose(), oy);
    res.r3y_um.row(i) = r3.r_um.transpose();
    res.m3y_um.row(i) = r3.m_um.transpose();
    res.r4y_um.row(i) = r4.r_um.transpose();
    res.m4y_um.row(i) = r4.m_um.transpose();
  }

  res.m_wxe_um = Eigen::MatrixXd::Zero(nx, ny);
  res.m_wye_um = Eigen::MatrixXd::Zero(nx, ny);
  if (res.rotation_corrected) {
    const auto& g = opts.geometry;
    // Eqs. (22), (24).
    res.m_wxe_um = (res.m2x_um - res.m1x_um) * (g.l_xw_mm / g.l_xs_mm);
    // Eq. (26) with Δm_y = m4_y - m3_y and l_yw(x) (see header).
    for (Eigen::Index i = 0; i < nx; ++i) {
      const double l_yw = g.l_yw_mm + g.l_yw_per_x * (scan.x_mm(i) - scan.x_mm(0));
      res.m_wye_um.row(i) = (res.m4y_um.row(i) - res.m3y_um.row(i)) * (l_yw / g.l_ys_mm);
    }
  }
  // Eq. (27), then Eq. (10).
  res.m_w_um = res.m2x_um + res.m4y_um - res.m_wxe_um - res.m_wye_um;
  res.w_um = scan.s0_1_um - res.m_w_um;
  res.gauge = "r(x_1) = 0 on every row and r(y_1) = 0 on every column (Eq. 9)";
  return res;
}

/// The joint estimate (displacement_joint.hpp) with per-point uncertainty and the rotation
/// decision (header).
TwoAxisResult joint(const TwoAxisScan& scan, const TwoAxisOptions& opts) {
  const Eigen::Index nx = scan.x_mm.size(), ny = scan.y_mm.size();
  const double N = static_cast<double>(nx * ny);
  const int px = static_cast<int>(std::lround(opts.displacement_x_mm / opts.dx_mm));
  const int py = static_cast<int>(std::lround(opts.displacement_y_mm / opts.dy_mm));
  const auto& g = opts.geometry;
  const double kx = g.l_xw_mm / g.l_xs_mm;
  Eigen::VectorXd ky(nx);
  for (Eigen::Index i = 0; i < nx; ++i)
    ky(i) = (g.l_yw_mm + g.l_yw_per_x * (scan.x_mm(i) - scan.x_mm(0))) / g.l_ys_mm;

  // Coefficients of m1..m4 in m_w, per point: with Eqs. (22)-(27), without (Eqs. 20-21), and
  // their difference b = m_w(on) − m_w(off) = −(m_wxe + m_wye): what w without them gets wrong.
  struct Coeffs {
    Eigen::MatrixXd c[4];
  };
  // Coefficients of m1, m2 (constant) and of m3, m4 (c + k·ky(x_i): l_yw may vary with x).
  auto coeffs = [&](double a1, double a2, double c3, double k3, double c4, double k4) {
    Coeffs c;
    for (auto& m : c.c)
      m.resize(nx, ny);
    for (Eigen::Index i = 0; i < nx; ++i) {
      c.c[0].row(i).setConstant(a1);
      c.c[1].row(i).setConstant(a2);
      c.c[2].row(i).setConstant(c3 + k3 * ky(i));
      c.c[3].row(i).setConstant(c4 + k4 * ky(i));
    }
    return c;
  };
  // Eq. (27): m_w = kx·m1 + (1 − kx)·m2 + ky·m3 + (1 − ky)·m4; Eqs. (20)-(21): m2 + m4.
  const Coeffs c_on = coeffs(kx, 1.0 - kx, 0.0, 1.0, 1.0, -1.0);
  const Coeffs c_off = coeffs(0.0, 1.0, 0.0, 0.0, 1.0, 0.0);
  const Coeffs c_b = coeffs(kx, -kx, 0.0, 1.0, 0.0, -1.0);

  // Tracks 0-3 = sensors 1-4; sensors 3, 4 along y: their matrices transposed (rows along y).
  const std::vector<ReferenceTrackScan> tracks = {
      {scan.s1_1_um, scan.s1_2_um, px, opts.dx_mm},
      {scan.s2_1_um, scan.s2_2_um, px, opts.dx_mm},
      {scan.s3_1_um.transpose(), scan.s3_2_um.transpose(), py, opts.dy_mm},
      {scan.s4_1_um.transpose(), scan.s4_2_um.transpose(), py, opts.dy_mm}};
  auto functional = [&](const Coeffs& c) {
    return MotionFunctional{c.c[0] / N, c.c[1] / N, c.c[2].transpose() / N, c.c[3].transpose() / N};
  };
  JointReferenceFit fit =
      fit_reference_tracks(tracks, {functional(c_on), functional(c_off), functional(c_b)});
  if (opts.chain_join == ChainJoin::least_roughness) {
    if (px > 1) join_chains(fit.tracks[0], px), join_chains(fit.tracks[1], px);
    if (py > 1) join_chains(fit.tracks[2], py), join_chains(fit.tracks[3], py);
  }
  // Per sensor, in nx × ny layout: m, var(m) per unit σ², ∂m/∂δ.
  Eigen::MatrixXd m[4], vm[4], dm[4];
  for (int k = 0; k < 4; ++k) {
    const auto& f = fit.tracks[static_cast<std::size_t>(k)];
    const bool along_y = k >= 2;
    m[k] = along_y ? Eigen::MatrixXd(f.m_um.transpose()) : f.m_um;
    vm[k] = along_y ? Eigen::MatrixXd(f.var_m.transpose()) : f.var_m;
    dm[k] = along_y ? Eigen::MatrixXd(f.dm_dd_um_per_mm.transpose()) : f.dm_dd_um_per_mm;
  }

  TwoAxisResult res;
  res.solver = TwoAxisSolver::joint;
  res.rotation_requested = opts.rotation;
  double rss = 0;
  int dof = 0;
  for (const auto& f : fit.tracks) {
    rss += f.rss_um2;
    dof += f.dof;
  }
  if (dof <= 0)
    throw std::invalid_argument(
        "two-axis displacement method: the grid has no redundant reference reading (it needs at "
        "least two rows and two columns) for the uncertainty");
  res.dof_reference = dof;
  res.sigma_reference_um = std::sqrt(rss / dof);
  const double s2 = rss / dof;
  const double sd2 = opts.displacement_sigma_mm * opts.displacement_sigma_mm;

  // Sensor 0: w = mean of its readings − m_w; σ0 given, from its repeat, or assumed.
  const bool repeat = scan.s0_2_um.size() != 0;
  const double n0 = repeat ? 2.0 : 1.0;
  const Eigen::MatrixXd s0 =
      repeat ? Eigen::MatrixXd(0.5 * (scan.s0_1_um + scan.s0_2_um)) : scan.s0_1_um;
  if (std::isfinite(opts.workpiece_sigma_um)) {
    res.sigma_workpiece_um = opts.workpiece_sigma_um;
    res.sigma_workpiece_source = "given";
  } else if (repeat && N > 1) {
    // S0_2 − S0_1 = offset + noise of variance 2σ0² (displacement_residuals.hpp).
    const Eigen::MatrixXd diff = scan.s0_2_um - scan.s0_1_um;
    const double rss0 = (diff.array() - diff.mean()).square().sum();
    res.sigma_workpiece_um = std::sqrt(rss0 / (2.0 * (N - 1)));
    res.sigma_workpiece_source =
        "sensor 0 repeat (dof " + std::to_string(static_cast<long>(N - 1)) + ")";
  } else {
    res.sigma_workpiece_um = res.sigma_reference_um;
    res.sigma_workpiece_source =
        "assumed equal to the reference sensors' (sensor 0 read once: record it in scan 2 or "
        "give its sigma)";
  }
  const double s02 = res.sigma_workpiece_um * res.sigma_workpiece_um;

  // m_w for a coefficient set, its per-point variance, and the variance of its mean over the grid.
  struct Combined {
    Eigen::MatrixXd value, var;
    double var_mean = 0;
  };
  auto combine = [&](const Coeffs& c, double functional_var) {
    Combined out;
    out.value = Eigen::MatrixXd::Zero(nx, ny);
    out.var = Eigen::MatrixXd::Zero(nx, ny);
    Eigen::MatrixXd dx_sens = Eigen::MatrixXd::Zero(nx, ny), dy_sens = dx_sens;
    for (int k = 0; k < 4; ++k) {
      out.value.array() += c.c[k].array() * m[k].array();
      out.var.array() += s2 * c.c[k].array().square() * vm[k].array();
      (k < 2 ? dx_sens : dy_sens).array() += c.c[k].array() * dm[k].array();
    }
    out.var.array() += sd2 * (dx_sens.array().square() + dy_sens.array().square());
    out.var_mean = s2 * functional_var +
                   sd2 * (dx_sens.mean() * dx_sens.mean() + dy_sens.mean() * dy_sens.mean());
    return out;
  };
  const Combined on = combine(c_on, fit.functional_var[0]);
  const Combined off = combine(c_off, fit.functional_var[1]);
  const Combined b = combine(c_b, fit.functional_var[2]);
  // Predicted mean squared error of w's shape (header).
  const double e_on = on.var.mean() + s02 / n0 - on.var_mean - s02 / (n0 * N);
  const double b_shape = (b.value.array() - b.value.mean()).square().mean();
  const double bias2 = std::max(0.0, b_shape - (b.var.mean() - b.var_mean));
  const double e_off = off.var.mean() + s02 / n0 - off.var_mean - s02 / (n0 * N) + bias2;
  res.predicted_rms_on_um = std::sqrt(std::max(0.0, e_on));
  res.predicted_rms_off_um = std::sqrt(std::max(0.0, e_off));
  res.rotation_bias_um = std::sqrt(bias2);
  res.rotation_terms_noise_um = std::sqrt(std::max(0.0, b.var.mean() - b.var_mean));
  res.rotation_corrected = opts.rotation == RotationCorrection::on ||
                           (opts.rotation == RotationCorrection::automatic && e_on < e_off);
  {
    std::ostringstream s;
    s.precision(3);
    s << "rotation correction " << (res.rotation_corrected ? "on" : "off") << " ("
      << to_string(opts.rotation) << "): predicted rms error of w's shape " << std::sqrt(e_on)
      << " um with Eqs. (22)-(27), " << std::sqrt(std::max(0.0, e_off))
      << " um without (rotation terms' shape " << std::sqrt(bias2) << " um)";
    res.rotation_note = s.str();
  }

  const Combined& chosen = res.rotation_corrected ? on : off;
  res.m_w_um = chosen.value;
  res.u_m_w_um = chosen.var.cwiseSqrt();
  res.w_um = s0 - res.m_w_um;  // Eq. (10), sensor 0 averaged over the scans that read it
  res.u_w_um = (chosen.var.array() + s02 / n0).sqrt();
  res.m1x_um = m[0];
  res.m2x_um = m[1];
  res.m3y_um = m[2];
  res.m4y_um = m[3];
  Eigen::MatrixXd* um[4] = {&res.u_m1x_um, &res.u_m2x_um, &res.u_m3y_um, &res.u_m4y_um};
  for (int k = 0; k < 4; ++k)
    *um[k] = (s2 * vm[k].array() + sd2 * dm[k].array().square()).sqrt();
  res.m_wxe_um = Eigen::MatrixXd::Zero(nx, ny);
  res.m_wye_um = Eigen::MatrixXd::Zero(nx, ny);
  res.u_m_wxe_um = Eigen::MatrixXd::Zero(nx, ny);
  res.u_m_wye_um = Eigen::MatrixXd::Zero(nx, ny);
  if (res.rotation_corrected) {
    // Eqs. (22), (24), (26); sensors independent, so the variances add.
    res.m_wxe_um = kx * (m[1] - m[0]);
    res.u_m_wxe_um =
        (kx * kx * s2 * (vm[0] + vm[1]).array() + sd2 * (kx * (dm[1] - dm[0])).array().square())
            .sqrt();
    for (Eigen::Index i = 0; i < nx; ++i) {
      res.m_wye_um.row(i) = ky(i) * (m[3].row(i) - m[2].row(i));
      res.u_m_wye_um.row(i) = (ky(i) * ky(i) * s2 * (vm[2].row(i) + vm[3].row(i)).array() +
                               sd2 * (ky(i) * (dm[3].row(i) - dm[2].row(i))).array().square())
                                  .sqrt();
    }
  }
  // Reference profiles: functions of one coordinate, repeated over the other for the grid layout.
  Eigen::MatrixXd* rr[4] = {&res.r1x_um, &res.r2x_um, &res.r3y_um, &res.r4y_um};
  Eigen::MatrixXd* ur[4] = {&res.u_r1x_um, &res.u_r2x_um, &res.u_r3y_um, &res.u_r4y_um};
  for (int k = 0; k < 4; ++k) {
    const auto& f = fit.tracks[static_cast<std::size_t>(k)];
    const Eigen::Index na = k < 2 ? nx : ny;
    const Eigen::VectorXd r = f.r_um.head(na);
    const Eigen::VectorXd u =
        (s2 * f.var_r.head(na).array() + sd2 * f.dr_dd_um_per_mm.head(na).array().square()).sqrt();
    if (k < 2) {
      *rr[k] = r.replicate(1, ny);
      *ur[k] = u.replicate(1, ny);
    } else {
      *rr[k] = r.transpose().replicate(nx, 1);
      *ur[k] = u.transpose().replicate(nx, 1);
    }
  }
  res.gauge = "r1_x, r2_x at x_1" + std::string(px > 1 ? "..x_p" : "") + " and r3_y, r4_y at y_1" +
              (py > 1 ? "..y_p" : "") + " set to 0 (Eq. 9): each r is determined up to a constant" +
              (px > 1 || py > 1 ? " per chain (chains joined by " +
                                      std::string(opts.chain_join == ChainJoin::least_roughness
                                                      ? "least roughness"
                                                      : "the given initial value") +
                                      "; u is that of the chains' first samples fixed)"
                                : std::string()) +
              ", each m_k up to its negative, and w up to the constant that m_w takes from them";
  return res;
}

}  // namespace

const char* to_string(TwoAxisSolver s) {
  return s == TwoAxisSolver::joint ? "joint" : "row-by-row";
}

const char* to_string(RotationCorrection r) {
  switch (r) {
    case RotationCorrection::on:
      return "on";
    case RotationCorrection::off:
      return "off";
    case RotationCorrection::automatic:
      return "auto";
  }
  return "?";
}

bool TwoAxisOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& msg) {
    if (why) *why = msg;
    return false;
  };
  std::string sub;
  if (!axis_options(dx_mm, displacement_x_mm, chain_join).is_valid(&sub))
    return fail("x axis: " + sub);
  if (!axis_options(dy_mm, displacement_y_mm, chain_join).is_valid(&sub))
    return fail("y axis: " + sub);
  const auto& g = geometry;
  if (!(std::isfinite(g.l_xs_mm) && g.l_xs_mm != 0))
    return fail("geometry.l_xs_mm = " + std::to_string(g.l_xs_mm) +
                ": must be finite and non-zero");
  if (!(std::isfinite(g.l_ys_mm) && g.l_ys_mm != 0))
    return fail("geometry.l_ys_mm = " + std::to_string(g.l_ys_mm) +
                ": must be finite and non-zero");
  if (!std::isfinite(g.l_xw_mm) || !std::isfinite(g.l_yw_mm) || !std::isfinite(g.l_yw_per_x))
    return fail("geometry: l_xw_mm, l_yw_mm and l_yw_per_x must be finite");
  if (!std::isnan(workpiece_sigma_um) &&
      !(std::isfinite(workpiece_sigma_um) && workpiece_sigma_um > 0))
    return fail("workpiece_sigma_um = " + std::to_string(workpiece_sigma_um) +
                ": must be > 0 (or NaN: estimated)");
  if (!(std::isfinite(displacement_sigma_mm) && displacement_sigma_mm >= 0))
    return fail("displacement_sigma_mm = " + std::to_string(displacement_sigma_mm) +
                ": must be finite and >= 0");
  return true;
}

TwoAxisResult separate_two_axis(const TwoAxisScan& scan, const TwoAxisOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("two-axis displacement method: " + why);
  const Eigen::Index nx = scan.x_mm.size(), ny = scan.y_mm.size();
  const std::pair<const char*, const Eigen::MatrixXd*> mats[] = {
      {"s0_1", &scan.s0_1_um}, {"s1_1", &scan.s1_1_um}, {"s1_2", &scan.s1_2_um},
      {"s2_1", &scan.s2_1_um}, {"s2_2", &scan.s2_2_um}, {"s3_1", &scan.s3_1_um},
      {"s3_2", &scan.s3_2_um}, {"s4_1", &scan.s4_1_um}, {"s4_2", &scan.s4_2_um}};
  for (const auto& [name, m] : mats) {
    if (m->rows() != nx || m->cols() != ny)
      throw std::invalid_argument(std::string("two-axis displacement method: ") + name + " is " +
                                  std::to_string(m->rows()) + "x" + std::to_string(m->cols()) +
                                  ", grid is " + std::to_string(nx) + "x" + std::to_string(ny));
    if (!m->allFinite())
      throw std::invalid_argument(
          std::string("two-axis displacement method: non-finite value in ") + name);
  }

  const auto t0 = std::chrono::steady_clock::now();
  TwoAxisResult res =
      opts.solver == TwoAxisSolver::joint ? joint(scan, opts) : row_by_row(scan, opts);
  res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

std::string TwoAxisResult::brief_report() const {
  std::ostringstream s;
  s << "two-axis displacement method (" << to_string(solver) << "): " << w_um.rows() << "x"
    << w_um.cols() << " grid, rotation "
    << (rotation_corrected ? "corrected (Eqs. 22-27)" : "not corrected (Eqs. 20-21)");
  if (w_um.size())
    s << ", w in [" << w_um.minCoeff() << ", " << w_um.maxCoeff() << "] um, m_w in ["
      << m_w_um.minCoeff() << ", " << m_w_um.maxCoeff() << "] um";
  if (u_w_um.size())
    s << ", u(w) " << u_w_um.minCoeff() << ".." << u_w_um.maxCoeff() << " um (sigma_hat "
      << sigma_reference_um << " um, dof " << dof_reference << "; sensor 0 " << sigma_workpiece_um
      << " um, " << sigma_workpiece_source << ")";
  if (!rotation_note.empty()) s << "\n  " << rotation_note;
  return s.str();
}

}  // namespace errsep::core

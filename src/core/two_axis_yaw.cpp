#include "errsep/core/two_axis_yaw.hpp"

#include <Eigen/Dense>
#include <boost/math/distributions/fisher_f.hpp>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "errsep/core/model_effect.hpp"
#include "errsep/core/noise.hpp"

namespace errsep::core {
namespace {

constexpr double kUmPerRadMm = 1000.0;

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("two-axis yaw: " + what);
}

double legendre(int k, double u) {
  double pkm1 = 0.0, pk = 1.0;
  for (int j = 0; j < k; ++j) {
    const double next = ((2.0 * j + 1.0) * u * pk - j * pkm1) / (j + 1.0);
    pkm1 = pk;
    pk = next;
  }
  return pk;
}

double unit(double x, double x0, double x1) {
  return x1 > x0 ? 2.0 * (x - x0) / (x1 - x0) - 1.0 : 0.0;
}

// ψ basis on the grid: nx·ny × K, row i + nx·j, column (k, l) = P_k(u_i)·P_l(v_j), (k, l) ≠ (0, 0)
// (a constant yaw cannot be told from the lateral pair's zero offset; see the header).
Eigen::MatrixXd yaw_basis(const Eigen::VectorXd& x, const Eigen::VectorXd& y, int dxg, int dyg) {
  const Eigen::Index nx = x.size(), ny = y.size();
  Eigen::MatrixXd B(nx * ny, (dxg + 1) * (dyg + 1) - 1);
  for (Eigen::Index j = 0; j < ny; ++j)
    for (Eigen::Index i = 0; i < nx; ++i) {
      const double u = unit(x(i), x(0), x(nx - 1)), v = unit(y(j), y(0), y(ny - 1));
      int c = 0;
      for (int k = 0; k <= dxg; ++k)
        for (int l = 0; l <= dyg; ++l)
          if (k + l > 0) B(i + nx * j, c++) = legendre(k, u) * legendre(l, v);
    }
  return B;
}

// Orthonormal basis of the complement of (1, 1, 1, 1): the four readings of a point less e_y.
Eigen::Matrix<double, 4, 3> complement_basis() {
  Eigen::Matrix<double, 4, 3> V;
  V.col(0) << 1, -1, 0, 0;
  V.col(1) << 1, 1, -2, 0;
  V.col(2) << 1, 1, 1, -3;
  for (int c = 0; c < 3; ++c)
    V.col(c).normalize();
  return V;
}

int steps_of(double len_mm, double dx_mm) {
  return static_cast<int>(std::lround(len_mm / dx_mm));
}

// The lateral pair as a linear model: projected readings y (3 per point), the g columns A and
// the yaw columns B (µm per µrad).
struct LateralSystem {
  Eigen::VectorXd y;
  Eigen::MatrixXd A, B;
};

LateralSystem lateral_system(const TwoAxisScan& scan, const LateralPairScan& lat,
                             const YawRefineOptions& o) {
  const Eigen::Index nx = scan.x_mm.size(), ny = scan.y_mm.size();
  const auto& g = o.geometry;
  const int ia = steps_of(g.lateral_a_mm, o.separation.dx_mm);
  const int ib = steps_of(g.lateral_b_mm, o.separation.dx_mm);
  const int p = steps_of(o.separation.displacement_x_mm, o.separation.dx_mm);
  const int lo = std::min(ia, ib);
  const int G = static_cast<int>(nx) - 1 + std::max(ia, ib) + p - lo + 1;
  const Eigen::Matrix<double, 4, 3> V = complement_basis();
  const Eigen::MatrixXd psi = yaw_basis(scan.x_mm, scan.y_mm, o.degree_x, o.degree_y);
  const Eigen::Index K = psi.cols();
  LateralSystem s;
  s.y.resize(3 * nx * ny);
  // Columns: the G lattice values of g, then the zero offset of sensor b against sensor a.
  s.A = Eigen::MatrixXd::Zero(3 * nx * ny, G + 1);
  s.B.resize(3 * nx * ny, K);
  const double Xk[4] = {g.lateral_a_mm, g.lateral_a_mm, g.lateral_b_mm, g.lateral_b_mm};
  for (Eigen::Index j = 0; j < ny; ++j)
    for (Eigen::Index i = 0; i < nx; ++i) {
      const Eigen::Index row = 3 * (i + nx * j);
      const Eigen::Vector4d u(lat.ua_1_um(i, j), lat.ua_2_um(i, j), lat.ub_1_um(i, j),
                              lat.ub_2_um(i, j));
      s.y.segment<3>(row) = V.transpose() * u;
      const int idx[4] = {static_cast<int>(i) + ia - lo, static_cast<int>(i) + ia + p - lo,
                          static_cast<int>(i) + ib - lo, static_cast<int>(i) + ib + p - lo};
      for (int q = 0; q < 4; ++q)
        s.A.block<3, 1>(row, idx[q]) += V.row(q).transpose();
      s.A.block<3, 1>(row, G) = V.row(2).transpose() + V.row(3).transpose();
      // ψ·X_k in µm for ψ in µrad; the common part ψ·(x_axis − x) cancels in V.
      Eigen::Vector4d z;
      for (int q = 0; q < 4; ++q)
        z(q) = 1e-6 * kUmPerRadMm * Xk[q];
      const Eigen::Vector3d vz = V.transpose() * z;
      for (Eigen::Index c = 0; c < K; ++c)
        s.B.block<3, 1>(row, c) = vz * psi(i + nx * j, c);
    }
  return s;
}

// Corrected copy of the scans for yaw ψ (rad, nx × ny), slopes from the separation `sep`.
TwoAxisScan corrected_scan(const TwoAxisScan& scan, const TwoAxisResult& sep,
                           const Eigen::MatrixXd& psi, const YawRefineOptions& o) {
  TwoAxisScan c = scan;
  const Eigen::Index nx = scan.x_mm.size(), ny = scan.y_mm.size();
  const auto& tg = o.separation.geometry;
  const auto& yg = o.geometry;
  const double dx = o.separation.dx_mm, dy = o.separation.dy_mm;
  const Eigen::Index p = steps_of(o.separation.displacement_x_mm, dx);
  const double s1 = tg.l_xs_mm - yg.axis_s_mm, s2 = -yg.axis_s_mm, s0 = tg.l_xw_mm - yg.axis_s_mm;
  for (Eigen::Index j = 0; j < ny; ++j) {
    const Eigen::VectorXd wrow_x = sep.w_um.col(j);
    const Eigen::VectorXd r1 = sep.r1x_um.col(j), r2 = sep.r2x_um.col(j);
    for (Eigen::Index i = 0; i < nx; ++i) {
      const double ps = psi(i, j);
      const Eigen::VectorXd wcol_y = sep.w_um.row(i).transpose();
      const double dwdx = grid_derivative(wrow_x, dx, i), dwdy = grid_derivative(wcol_y, dy, j);
      const double dxi0 = ps * s0, deta0 = ps * (scan.x_mm(i) - yg.axis_x_mm);
      c.s0_1_um(i, j) -= dwdx * dxi0 + dwdy * deta0;
      if (c.s0_2_um.size()) c.s0_2_um(i, j) -= dwdx * dxi0 + dwdy * deta0;
      // Reference slopes at x and at x + d (the last sample's slope beyond the grid).
      const Eigen::Index i2 = std::min(i + p, nx - 1);
      c.s1_1_um(i, j) -= grid_derivative(r1, dx, i) * ps * s1;
      c.s1_2_um(i, j) -= grid_derivative(r1, dx, i2) * ps * s1;
      c.s2_1_um(i, j) -= grid_derivative(r2, dx, i) * ps * s2;
      c.s2_2_um(i, j) -= grid_derivative(r2, dx, i2) * ps * s2;
    }
  }
  return c;
}

}  // namespace

bool YawGeometry::is_valid(double dx_mm, std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(std::isfinite(axis_s_mm) && std::isfinite(axis_x_mm) && std::isfinite(lateral_a_mm) &&
        std::isfinite(lateral_b_mm)))
    return fail("geometry values must be finite");
  if (!(dx_mm > 0)) return fail("dx must be > 0");
  for (double v : {lateral_a_mm, lateral_b_mm}) {
    const double q = v / dx_mm;
    if (std::abs(q - std::round(q)) > 1e-6)
      return fail("lateral sensor position " + std::to_string(v) + " mm is not a multiple of dx " +
                  std::to_string(dx_mm) + " mm");
  }
  if (std::lround(lateral_a_mm / dx_mm) == std::lround(lateral_b_mm / dx_mm))
    return fail("lateral_a_mm and lateral_b_mm must differ (the pair's base)");
  return true;
}

bool YawRefineOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!separation.is_valid(why)) return false;
  if (!geometry.is_valid(separation.dx_mm, why)) return false;
  if (degree_x < 0 || degree_y < 0) return fail("degree_x, degree_y must be >= 0");
  if (!(alpha > 0 && alpha < 1)) return fail("alpha must be in (0, 1)");
  if (iterations < 1) return fail("iterations must be >= 1");
  if (!(rank_tol > 0 && rank_tol < 1)) return fail("rank_tol must be in (0, 1)");
  return true;
}

YawSimData simulate_two_axis_yaw(const TwoAxisTruth& truth, const YawTruth& yaw,
                                 const TwoAxisSimOptions& opts, const YawGeometry& geometry) {
  std::string why;
  require(opts.is_valid(&why), why);
  require(geometry.is_valid(opts.dx_mm, &why), why);
  require(opts.displacement_bias_mm == 0 && opts.displacement_sigma_mm == 0,
          "the yaw simulation uses the nominal traverse d: displacement_bias_mm and "
          "displacement_sigma_mm must be 0");
  require(yaw.yaw_rad && yaw.side_um && yaw.lateral_um, "every yaw truth function must be set");
  YawSimData d;
  d.two_axis = simulate_two_axis(truth, opts);
  TwoAxisScan& s = d.two_axis.scan;
  const int nx = opts.nx, ny = opts.ny;
  const auto& g = opts.geometry;
  const double dX = opts.displacement_x_mm;
  d.yaw_rad.resize(nx, ny);
  LateralPairScan& L = d.lateral;
  for (auto* m : {&L.ua_1_um, &L.ua_2_um, &L.ub_1_um, &L.ub_2_um})
    m->resize(nx, ny);
  NoiseSource rng(opts.seed ^ 0x9e3779b97f4a7c15ULL);  // the lateral pair's own stream
  const double se = opts.eddy_sensor.noise_sigma_um;
  for (int q = 0; q < 2; ++q)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const double x = s.x_mm(i), y = s.y_mm(j), psi = yaw.yaw_rad(x, y);
        const double ey = yaw.lateral_um(x, y);
        auto lateral = [&](double X) {
          return yaw.side_um(x + X + q * dX) + ey +
                 kUmPerRadMm * psi * (X - (x - geometry.axis_x_mm));
        };
        (q == 0 ? L.ua_1_um : L.ua_2_um)(i, j) =
            lateral(geometry.lateral_a_mm) + yaw.offset_a_um + rng.normal(se);
        (q == 0 ? L.ub_1_um : L.ub_2_um)(i, j) =
            lateral(geometry.lateral_b_mm) + yaw.offset_b_um + rng.normal(se);
      }
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const double x = s.x_mm(i), y = s.y_mm(j), psi = yaw.yaw_rad(x, y);
      d.yaw_rad(i, j) = psi;
      const double dxi0 = psi * (g.l_xw_mm - geometry.axis_s_mm);
      const double deta0 = psi * (x - geometry.axis_x_mm);
      const double dw = truth.w_um(x + dxi0, y + deta0) - truth.w_um(x, y);
      s.s0_1_um(i, j) += dw;
      d.two_axis.w_um(i, j) = truth.w_um(x, y);  // w stays the map at the nominal points
      // Sensor 0 in scan 2, when recorded, sees the same yaw term.
      if (s.s0_2_um.size()) s.s0_2_um(i, j) += dw;
      const double dxi1 = psi * (g.l_xs_mm - geometry.axis_s_mm);
      const double dxi2 = psi * (0.0 - geometry.axis_s_mm);
      s.s1_1_um(i, j) += truth.r1x_um(x + dxi1) - truth.r1x_um(x);
      s.s1_2_um(i, j) += truth.r1x_um(x + dX + dxi1) - truth.r1x_um(x + dX);
      s.s2_1_um(i, j) += truth.r2x_um(x + dxi2) - truth.r2x_um(x);
      s.s2_2_um(i, j) += truth.r2x_um(x + dX + dxi2) - truth.r2x_um(x + dX);
    }
  return d;
}

TwoAxisYawResult refine_two_axis_yaw(const TwoAxisScan& scan, const LateralPairScan& lat,
                                     const YawRefineOptions& o) {
  std::string why;
  require(o.is_valid(&why), why);
  const Eigen::Index nx = scan.x_mm.size(), ny = scan.y_mm.size();
  for (const Eigen::MatrixXd* m : {&lat.ua_1_um, &lat.ua_2_um, &lat.ub_1_um, &lat.ub_2_um}) {
    require(m->rows() == nx && m->cols() == ny,
            "lateral pair matrices must be " + std::to_string(nx) + "x" + std::to_string(ny) +
                " like the grid, got " + std::to_string(m->rows()) + "x" +
                std::to_string(m->cols()));
    require(m->allFinite(), "non-finite lateral pair reading");
  }
  TwoAxisYawResult res;
  res.before = separate_two_axis(scan, o.separation);
  res.after = res.before;
  res.yaw_rad = Eigen::MatrixXd::Zero(nx, ny);
  for (int k = 0; k <= o.degree_x; ++k)
    for (int l = 0; l <= o.degree_y; ++l)
      if (k + l > 0)
        res.parameter_names.push_back("c_" + std::to_string(k) + "_" + std::to_string(l) + "_urad");

  const LateralSystem sys = lateral_system(scan, lat, o);
  const Eigen::Index n = sys.y.size(), K = sys.B.cols();
  // Base model: g only.  Its constant cancels in every projected row, so g at the first lattice
  // point is fixed to 0 (its column dropped); the rest has full column rank (the lattice is
  // connected by the traverse d), checked below.
  const Eigen::MatrixXd Ag = sys.A.rightCols(sys.A.cols() - 1);
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qa(Ag);
  require(qa.rank() == Ag.cols(), "the side face lattice is not connected by the traverse d");
  auto side = [&](const Eigen::VectorXd& gv) {  // ĝ without the offset, g(first point) = 0
    Eigen::VectorXd full(gv.size());
    full << 0.0, gv.head(gv.size() - 1);
    return full;
  };
  const Eigen::VectorXd g0 = qa.solve(sys.y);
  const Eigen::VectorXd r0 = sys.y - Ag * g0;
  res.rss_before_um2 = r0.squaredNorm();
  res.dof_before = static_cast<int>(n - qa.rank());
  res.sigma_before_um = std::sqrt(res.rss_before_um2 / std::max(1, res.dof_before));
  res.rms_before_um = std::sqrt(res.rss_before_um2 / static_cast<double>(n));
  res.side_um = side(g0);
  // Yaw columns with the base model projected out, scaled to unit norm.
  Eigen::MatrixXd Bp = sys.B - Ag * qa.solve(sys.B);
  Eigen::VectorXd D(K);
  for (Eigen::Index c = 0; c < K; ++c) {
    D(c) = sys.B.col(c).norm();
    Bp.col(c) /= D(c);
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(Bp, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::VectorXd& sv = svd.singularValues();
  int kid = 0;
  for (Eigen::Index j = 0; j < sv.size(); ++j)
    if (sv(j) > o.rank_tol * std::max(1.0, sv(0))) ++kid;
  res.identifiable = kid;
  Eigen::VectorXd cs = Eigen::VectorXd::Zero(K);  // scaled parameters
  Eigen::MatrixXd covs = Eigen::MatrixXd::Zero(K, K);
  double fit = 0;
  for (int j = 0; j < kid; ++j) {
    const double cj = svd.matrixU().col(j).dot(r0);
    fit += cj * cj;
    cs += svd.matrixV().col(j) * (cj / sv(j));
    covs += svd.matrixV().col(j) * svd.matrixV().col(j).transpose() / (sv(j) * sv(j));
  }
  res.rss_after_um2 = std::max(0.0, res.rss_before_um2 - fit);
  res.dof_after = res.dof_before - kid;
  res.sigma_after_um = std::sqrt(res.rss_after_um2 / std::max(1, res.dof_after));
  res.rms_after_um = std::sqrt(res.rss_after_um2 / static_cast<double>(n));
  if (kid > 0 && res.dof_after > 0 && res.rss_after_um2 > 0) {
    res.F = (fit / kid) / (res.rss_after_um2 / res.dof_after);
    boost::math::fisher_f_distribution<double> dist(kid, res.dof_after);
    res.p_value = boost::math::cdf(boost::math::complement(dist, res.F));
  }
  res.parameters_urad = cs.cwiseQuotient(D);
  res.covariance_urad2 = D.cwiseInverse().asDiagonal() * covs * D.cwiseInverse().asDiagonal() *
                         (res.sigma_after_um * res.sigma_after_um);
  res.u_parameters_urad = res.covariance_urad2.diagonal().cwiseSqrt();
  res.yaw_added = res.p_value < o.alpha;
  if (!res.yaw_added) return res;

  res.side_um = side(qa.solve(sys.y - sys.B * res.parameters_urad));
  const Eigen::MatrixXd basis = yaw_basis(scan.x_mm, scan.y_mm, o.degree_x, o.degree_y);
  const Eigen::VectorXd psi = 1e-6 * (basis * res.parameters_urad);
  for (Eigen::Index j = 0; j < ny; ++j)
    for (Eigen::Index i = 0; i < nx; ++i)
      res.yaw_rad(i, j) = psi(i + nx * j);
  // Fixed point: the slopes come from the current separation, which improves with each pass.
  TwoAxisResult sep = res.before;
  for (int it = 0; it < o.iterations; ++it)
    sep = separate_two_axis(corrected_scan(scan, sep, res.yaw_rad, o), o.separation);
  res.after = sep;
  return res;
}

std::string TwoAxisYawResult::brief_report() const {
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "two-axis yaw: lateral pair residual RMS %.4g -> %.4g um (sigma_hat %.3g -> %.3g "
                "um, dof %d -> %d), yaw F = %.4g, p = %.3g, %d of %zu directions identifiable: %s",
                rms_before_um, rms_after_um, sigma_before_um, sigma_after_um, dof_before, dof_after,
                F, p_value, identifiable, parameter_names.size(),
                yaw_added ? "yaw added, scans corrected" : "no yaw added");
  return buf;
}

}  // namespace errsep::core

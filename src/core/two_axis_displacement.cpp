#include "errsep/core/two_axis_displacement.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace errsep::core {
namespace {

DisplacementOptions axis_options(double dx, double d, ChainJoin join) {
  DisplacementOptions o;
  o.sample_interval_mm = dx;
  o.displacement_mm = d;
  o.chain_join = join;
  return o;
}

}  // namespace

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

  const DisplacementOptions ox = axis_options(opts.dx_mm, opts.displacement_x_mm, opts.chain_join);
  const DisplacementOptions oy = axis_options(opts.dy_mm, opts.displacement_y_mm, opts.chain_join);
  TwoAxisResult res;
  res.rotation_corrected = opts.correct_rotation;
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
  if (opts.correct_rotation) {
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
  return res;
}

std::string TwoAxisResult::brief_report() const {
  std::ostringstream s;
  s << "two-axis displacement method: " << w_um.rows() << "x" << w_um.cols() << " grid, rotation "
    << (rotation_corrected ? "corrected (Eqs. 22-27)" : "not corrected (Eqs. 20-21)");
  if (w_um.size())
    s << ", w in [" << w_um.minCoeff() << ", " << w_um.maxCoeff() << "] um, m_w in ["
      << m_w_um.minCoeff() << ", " << m_w_um.maxCoeff() << "] um";
  return s.str();
}

}  // namespace errsep::core

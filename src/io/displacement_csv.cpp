#include "errsep/io/displacement_csv.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>

#include "errsep/io/plausibility.hpp"
#include "errsep/io/raw_scan_csv.hpp"

namespace errsep::io {
namespace {

std::string num(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

Eigen::VectorXd to_vec(const std::vector<double>& v) {
  return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

std::size_t line_of(const CsvTable& t, std::size_t row) {
  return row < t.row_line.size() ? t.row_line[row] : 0;
}

/// Checks that x is strictly increasing at a constant interval; returns the interval.
double uniform_interval(const CsvTable& t, const std::vector<double>& x,
                        const std::filesystem::path& file, const char* col) {
  if (x.size() < 2) throw CsvError(file, 0, std::string("need at least 2 rows of ") + col);
  const double dx = x[1] - x[0];
  if (!(dx > 0))
    throw CsvError(
        file, line_of(t, 1),
        std::string(col) + " must increase (found " + num(x[0]) + " then " + num(x[1]) + ")");
  const double tol = 1e-6 * std::max(1.0, std::abs(dx));
  for (std::size_t k = 1; k < x.size(); ++k)
    if (std::abs(x[k] - x[k - 1] - dx) > tol)
      throw CsvError(file, line_of(t, k),
                     std::string(col) + " = " + num(x[k]) + " after " + num(x[k - 1]) +
                         " breaks the sampling interval " + num(dx) +
                         " set by the first two rows (samples must be uniform and in order)");
  return dx;
}

/// The grid positions of one coordinate: v_min + k·d, k = 0..K, with d the smallest step between
/// distinct values.  A value off that lattice is an error at its line; lattice positions with no
/// row are left to the completeness check (a ragged grid).  Sets *spacing.
std::vector<double> grid_axis(const CsvTable& t, const std::vector<double>& v,
                              const std::filesystem::path& file, const char* col, double* spacing) {
  std::vector<double> s = v;
  std::sort(s.begin(), s.end());
  std::vector<double> u;
  for (double a : s)
    if (u.empty() || std::abs(a - u.back()) > 1e-6 * std::max(1.0, std::abs(a))) u.push_back(a);
  if (u.size() < 2)
    throw CsvError(file, 0, std::string("the grid has a single ") + col + " value; need >= 2");
  double d = u[1] - u[0];
  for (std::size_t k = 1; k < u.size(); ++k)
    d = std::min(d, u[k] - u[k - 1]);
  for (std::size_t r = 0; r < v.size(); ++r) {
    const double q = (v[r] - u[0]) / d;
    if (std::abs(q - std::round(q)) > 1e-6) {
      std::string seen;
      for (std::size_t k = 0; k < u.size() && k < 8; ++k)
        seen += (k ? ", " : "") + num(u[k]);
      if (u.size() > 8) seen += ", ...";
      throw CsvError(file, line_of(t, r),
                     std::string(col) + " = " + num(v[r]) + " is not on the grid " + num(u[0]) +
                         " + k*" + num(d) + ": the " + col + " values (" + seen +
                         ") are not evenly spaced");
    }
  }
  // Every lattice position needs a row: a span that needs more positions than the file has rows
  // is a ragged grid (checked here, before the lattice is allocated: 0, 5, 1e308 would need
  // 2e307 positions).
  const double positions = std::round((u.back() - u[0]) / d) + 1;
  if (!(positions <= static_cast<double>(v.size()))) {
    double missing = u[0] + d;
    for (std::size_t k = 0; k + 1 < u.size(); ++k)
      if (u[k + 1] - u[k] > 1.5 * d) {
        missing = u[k] + d;
        break;
      }
    throw CsvError(file, 0,
                   std::string("ragged grid: ") + col + " from " + num(u[0]) + " to " +
                       num(u.back()) + " in steps of " + num(d) + " needs " + num(positions) +
                       " values, the file has " + std::to_string(v.size()) + " rows; missing (" +
                       col + " = " + num(missing) + ")");
  }
  const auto count = static_cast<std::size_t>(positions);
  std::vector<double> axis(count);
  for (std::size_t k = 0; k < count; ++k)
    axis[k] = u[0] + static_cast<double>(k) * d;
  *spacing = d;
  return axis;
}

/// Every reading column of the table (a name "<sensor>_..._um" other than x_mm, y_mm) within its
/// sensor's range (the file's metadata, else the default bound): before anything is computed.
void check_reading_columns(const CsvTable& t, const std::filesystem::path& file) {
  for (const auto& c : t.columns) {
    if (c == "x_mm" || c == "y_mm" || c.size() < 4 || c.compare(c.size() - 3, 3, "_um") != 0)
      continue;
    const std::string sensor = c.substr(0, c.find('_'));
    check_readings(t, c, reading_range(t, sensor, file), file, false);
  }
}

std::size_t index_of(const std::vector<double>& axis, double v) {
  const auto it = std::lower_bound(axis.begin(), axis.end(), v - 1e-6 * std::max(1.0, std::abs(v)));
  return static_cast<std::size_t>(it - axis.begin());
}

}  // namespace

OneAxisInput read_one_axis_csv(const std::filesystem::path& file) {
  CsvReadOptions lenient;
  lenient.allow_non_finite = true;  // the raw-scan reader decides about nan (incomplete scans)
  lenient.min_rows = 2;
  const CsvTable t = read_csv(file, lenient);
  OneAxisInput in;
  std::vector<double> x;
  if (t.meta("format")) {
    // Written by a scan: the raw-scan reader checks format, completeness and d_mm.
    const RawDisplacementScan raw = read_raw_displacement_csv(file);
    x = raw.x_mm;
    in.s1_1_um = to_vec(raw.s1_scan1_um);
    in.s2_1_um = to_vec(raw.s2_scan1_um);
    in.s2_2_um = to_vec(raw.s2_scan2_um);
    in.s1_2_um = to_vec(raw.s1_scan2_um);
    in.d_mm = raw.d_mm;
    in.scan2_order = raw.scan2_order;
  } else {
    const CsvTable strict = read_csv(file, CsvReadOptions{false, 2});  // nan -> file:line
    check_reading_columns(strict, file);
    x = strict.column("x_mm", file);
    in.s1_1_um = to_vec(strict.column("s1_scan1_um", file));
    in.s2_1_um = to_vec(strict.column("s2_scan1_um", file));
    in.s2_2_um = to_vec(strict.column("s2_scan2_um", file));
    if (strict.find_column("s1_scan2_um")) in.s1_2_um = to_vec(strict.column("s1_scan2_um", file));
    in.d_mm = strict.meta_number("d_mm", file);
  }
  in.dx_mm = uniform_interval(t, x, file, "x_mm");
  in.x_mm = to_vec(x);
  return in;
}

ThreePointInput read_three_point_csv(const std::filesystem::path& file) {
  const CsvTable t = read_csv(file, CsvReadOptions{false, 2});
  check_reading_columns(t, file);
  ThreePointInput in;
  const auto x = t.column("x_mm", file);
  const char* cols[3] = {"m1_um", "m2_um", "m3_um"};
  in.m_um.resize(static_cast<Eigen::Index>(t.rows.size()), 3);
  for (int j = 0; j < 3; ++j)
    in.m_um.col(j) = to_vec(t.column(cols[j], file));
  in.dx_mm = uniform_interval(t, x, file, "x_mm");
  in.x_mm = to_vec(x);
  return in;
}

TwoAxisInput read_two_axis_csv(const std::filesystem::path& file) {
  const CsvTable t = read_csv(file, CsvReadOptions{false, 4});
  check_reading_columns(t, file);
  const auto x = t.column("x_mm", file), y = t.column("y_mm", file);
  const char* names[9] = {"s0_scan1_um", "s1_scan1_um", "s1_scan2_um", "s2_scan1_um", "s2_scan2_um",
                          "s3_scan1_um", "s3_scan2_um", "s4_scan1_um", "s4_scan2_um"};
  std::vector<std::vector<double>> cols;
  for (const char* n : names)
    cols.push_back(t.column(n, file));
  // Optional columns: sensor 0 in scan 2, scan 1's reading time, the lateral pair (all or none).
  const char* lateral_names[4] = {"sa_scan1_um", "sa_scan2_um", "sb_scan1_um", "sb_scan2_um"};
  int lateral_present = 0;
  for (const char* n : lateral_names)
    lateral_present += t.find_column(n) ? 1 : 0;
  if (lateral_present > 0 && lateral_present < 4)
    for (const char* n : lateral_names)
      if (!t.find_column(n))
        throw CsvError(file, 0,
                       std::string("missing column '") + n +
                           "': the lateral sensor pair needs all four of sa_scan1_um, "
                           "sa_scan2_um, sb_scan1_um, sb_scan2_um");
  std::vector<const char*> optional_names;
  if (t.find_column("s0_scan2_um")) optional_names.push_back("s0_scan2_um");
  if (t.find_column("t_scan1_s")) optional_names.push_back("t_scan1_s");
  if (lateral_present == 4)
    for (const char* n : lateral_names)
      optional_names.push_back(n);
  std::vector<std::vector<double>> opt_cols;
  for (const char* n : optional_names)
    opt_cols.push_back(t.column(n, file));
  TwoAxisInput in;
  const auto xs = grid_axis(t, x, file, "x_mm", &in.dx_mm);
  const auto ys = grid_axis(t, y, file, "y_mm", &in.dy_mm);
  const auto nx = static_cast<Eigen::Index>(xs.size()), ny = static_cast<Eigen::Index>(ys.size());
  if (xs.size() * ys.size() > 4 * t.rows.size())  // before allocating nx x ny matrices
    throw CsvError(file, 0,
                   "ragged grid: " + std::to_string(nx) + " x values times " + std::to_string(ny) +
                       " y values need " + std::to_string(nx * ny) + " points, the file has " +
                       std::to_string(t.rows.size()));
  core::TwoAxisScan& s = in.scan;
  s.x_mm = to_vec(xs);
  s.y_mm = to_vec(ys);
  Eigen::MatrixXd* mats[9] = {&s.s0_1_um, &s.s1_1_um, &s.s1_2_um, &s.s2_1_um, &s.s2_2_um,
                              &s.s3_1_um, &s.s3_2_um, &s.s4_1_um, &s.s4_2_um};
  for (auto* m : mats)
    m->setZero(nx, ny);
  std::vector<Eigen::MatrixXd> opt_mats(optional_names.size(), Eigen::MatrixXd::Zero(nx, ny));
  std::vector<std::size_t> seen_line(static_cast<std::size_t>(nx * ny), 0);
  for (std::size_t r = 0; r < t.rows.size(); ++r) {
    const std::size_t i = index_of(xs, x[r]), j = index_of(ys, y[r]);
    std::size_t& seen = seen_line[i * static_cast<std::size_t>(ny) + j];
    if (seen)
      throw CsvError(file, line_of(t, r),
                     "grid point (x_mm = " + num(x[r]) + ", y_mm = " + num(y[r]) +
                         ") appears again (first at line " + std::to_string(seen) + ")");
    seen = line_of(t, r) ? line_of(t, r) : r + 1;
    for (int c = 0; c < 9; ++c)
      (*mats[c])(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = cols[c][r];
    for (std::size_t c = 0; c < opt_mats.size(); ++c)
      opt_mats[c](static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = opt_cols[c][r];
  }
  for (Eigen::Index j = 0; j < ny; ++j)
    for (Eigen::Index i = 0; i < nx; ++i)
      if (!seen_line[static_cast<std::size_t>(i * ny + j)])
        throw CsvError(file, 0,
                       "ragged grid: " + std::to_string(nx) + " x values times " +
                           std::to_string(ny) + " y values need " + std::to_string(nx * ny) +
                           " points, the file has " + std::to_string(t.rows.size()) +
                           "; missing (x_mm = " + num(xs[static_cast<std::size_t>(i)]) +
                           ", y_mm = " + num(ys[static_cast<std::size_t>(j)]) + ")");
  for (std::size_t c = 0; c < optional_names.size(); ++c) {
    const std::string n = optional_names[c];
    if (n == "s0_scan2_um") s.s0_2_um = opt_mats[c];
    if (n == "t_scan1_s") in.t_scan1_s = opt_mats[c];
  }
  if (lateral_present == 4) {
    core::LateralPairScan lat;
    const std::size_t first = optional_names.size() - 4;
    lat.ua_1_um = opt_mats[first];
    lat.ua_2_um = opt_mats[first + 1];
    lat.ub_1_um = opt_mats[first + 2];
    lat.ub_2_um = opt_mats[first + 3];
    in.lateral = std::move(lat);
  }
  return in;
}

CsvTable displacement_residuals_csv(const core::DisplacementResiduals& r, bool two_axis) {
  CsvTable t;
  t.set_meta("errsep",
             "displacement method residuals (Haramiishi 2024): the redundant equations, "
             "core/displacement_residuals.hpp");
  t.set_meta("units", two_axis ? "x, y in mm; value and residual in um"
                               : "x in mm; value and residual in um");
  t.set_meta("columns",
             "family: index of the family below; sensor: the paper's sensor number; scan: 1 or 2 "
             "for one reading, 0 for scan 2 minus scan 1; run: 1-based in repeated runs, 0 = mean "
             "of the runs; order: time order within the family; value: the redundant quantity; "
             "residual: value minus the least-squares fit of its shared unknowns");
  t.set_meta("runs", std::to_string(r.runs));
  t.set_meta("dof", std::to_string(r.dof));
  auto g = [](double v) {
    std::ostringstream s;
    s.precision(4);
    s << v;
    return s.str();
  };
  std::ostringstream verdict;
  if (r.families.empty())
    verdict << "nothing to test";
  else
    verdict << (r.white ? "white" : "not white: the displacement model lacks something")
            << " (alpha " << g(r.alpha)
            << (r.families.size() > 1 ? " over the families, Bonferroni)" : ")");
  t.set_meta("verdict", verdict.str());
  if (!r.note.empty()) t.set_meta("note", r.note);
  std::vector<std::vector<double>> rows;
  for (std::size_t fi = 0; fi < r.families.size(); ++fi) {
    const auto& f = r.families[fi];
    const std::string key = "family_" + std::to_string(fi + 1);
    t.set_meta(key, std::string(core::to_string(f.kind)) + ": " + f.equation);
    t.set_meta(key + "_dof",
               std::to_string(f.dof) + " (" + std::to_string(f.equations) + " equations)");
    if (f.dof > 0)
      t.set_meta(key + "_sigma_um", g(f.sigma_um) + " (per reading, pooled; " + g(f.sigma_low_um) +
                                        " to " + g(f.sigma_high_um) + " at 95 %)");
    for (std::size_t c = 0; c < f.channels.size(); ++c) {
      const auto& ch = f.channels[c];
      t.set_meta(
          key + "_sensor_" + std::to_string(ch.sensor) +
              (ch.scan ? "_scan" + std::to_string(ch.scan) : std::string()),
          ch.name + ": dof " + std::to_string(ch.dof) + ", sigma_hat " + g(ch.sigma_um) + " um");
      if (f.kind == core::RedundancyKind::workpiece_repeat && ch.group_mean_um.size() == 1 &&
          ch.dof > 0) {
        const double u = std::sqrt(ch.rss_um2 / ch.dof / static_cast<double>(ch.value_um.size()));
        t.set_meta(key + "_offset_um",
                   g(ch.group_mean_um(0)) + " +- " + g(u) +
                       " (scan 2 minus scan 1: a sensor zero shift or a table that moved)");
      }
    }
    const auto& w = f.whiteness;
    if (f.dof > 0) {
      std::ostringstream s;
      s << (w.white ? "white" : "not white") << ", p = " << g(w.p_value) << " (Ljung-Box "
        << g(w.p_ljung_box) << ", periodogram peak " << g(w.p_periodogram)
        << ", cumulative periodogram " << g(w.p_cumulative_periodogram) << ", runs " << g(w.p_runs)
        << ", local excess " << g(w.p_local) << ")";
      if (!w.rejected_by.empty()) s << "; rejected by " << w.rejected_by;
      t.set_meta(key + "_whiteness", s.str());
      std::ostringstream l;
      l << "z = " << g(w.local_z) << " over " << f.local_instants
        << " instants centred at x = " << g(f.local_x_mm) << " mm";
      if (two_axis) l << ", y = " << g(f.local_y_mm) << " mm";
      t.set_meta(key + "_local_excess", l.str());
    }
    for (const auto& ch : f.channels)
      for (Eigen::Index k = 0; k < ch.value_um.size(); ++k) {
        std::vector<double> row = {static_cast<double>(fi + 1),  static_cast<double>(ch.sensor),
                                   static_cast<double>(ch.scan), static_cast<double>(f.run(k)),
                                   static_cast<double>(k + 1),   f.x_mm(k)};
        if (two_axis) row.push_back(f.y_mm(k));
        row.push_back(ch.value_um(k));
        row.push_back(ch.residual_um(k));
        rows.push_back(std::move(row));
      }
  }
  t.columns = {"family", "sensor", "scan", "run", "order", "x_mm"};
  if (two_axis) t.columns.push_back("y_mm");
  t.columns.push_back("value_um");
  t.columns.push_back("residual_um");
  t.rows = std::move(rows);
  return t;
}

CsvTable one_axis_result_csv(const Eigen::VectorXd& x_mm, const core::DisplacementResult& r) {
  CsvTable t;
  t.set_meta("errsep", "displacement method, one axis (Haramiishi 2024 Eqs. 1-9)");
  t.set_meta("step_ratio", std::to_string(r.step_ratio));
  auto col = [&](const char* n, const Eigen::VectorXd& v) {
    t.add_column(n, std::vector<double>(v.data(), v.data() + v.size()));
  };
  col("x_mm", x_mm);
  col("r_um", r.r_um);
  col("m_um", r.m_um);
  col("w_um", r.w_um);
  return t;
}

CsvTable one_axis_result_csv(const Eigen::VectorXd& x_mm, const core::OneAxisJointResult& j) {
  CsvTable t = one_axis_result_csv(x_mm, j.estimate);
  t.set_meta("solver", "joint least squares (core/displacement_joint.hpp)");
  t.set_meta("gauge", j.gauge);
  t.set_meta("reading_sigma_um", std::isfinite(j.sigma_um) ? std::to_string(j.sigma_um) : "none");
  t.set_meta("sigma_source", j.sigma_source);
  if (j.u_w_um.size()) {
    t.set_meta("uncertainty", "u_*: standard uncertainty (k = 1) of each value in the gauge");
    for (const auto& [n, v] : {std::pair{"u_r_um", &j.u_r_um}, std::pair{"u_m_um", &j.u_m_um},
                               std::pair{"u_w_um", &j.u_w_um}})
      t.add_column(n, std::vector<double>(v->data(), v->data() + v->size()));
  }
  return t;
}

CsvTable two_axis_result_csv(const core::TwoAxisScan& scan, const core::TwoAxisResult& r) {
  CsvTable t;
  t.set_meta("errsep", "displacement method, two axes (Haramiishi 2024 Eqs. 10-27)");
  t.set_meta("rotation_correction", r.rotation_corrected ? "on" : "off");
  t.set_meta("solver", core::to_string(r.solver));
  if (!r.rotation_note.empty()) t.set_meta("rotation_decision", r.rotation_note);
  if (!r.gauge.empty()) t.set_meta("gauge", r.gauge);
  const Eigen::Index nx = scan.x_mm.size(), ny = scan.y_mm.size();
  auto flat = [&](const Eigen::MatrixXd& m) {
    std::vector<double> v;
    v.reserve(static_cast<std::size_t>(nx * ny));
    for (Eigen::Index j = 0; j < ny; ++j)
      for (Eigen::Index i = 0; i < nx; ++i)
        v.push_back(m(i, j));
    return v;
  };
  Eigen::MatrixXd xg(nx, ny), yg(nx, ny);
  for (Eigen::Index j = 0; j < ny; ++j)
    for (Eigen::Index i = 0; i < nx; ++i)
      xg(i, j) = scan.x_mm(i), yg(i, j) = scan.y_mm(j);
  t.add_column("x_mm", flat(xg));
  t.add_column("y_mm", flat(yg));
  t.add_column("w_um", flat(r.w_um));
  t.add_column("m_w_um", flat(r.m_w_um));
  t.add_column("m1x_um", flat(r.m1x_um));
  t.add_column("m2x_um", flat(r.m2x_um));
  t.add_column("m3y_um", flat(r.m3y_um));
  t.add_column("m4y_um", flat(r.m4y_um));
  t.add_column("m_wxe_um", flat(r.m_wxe_um));
  t.add_column("m_wye_um", flat(r.m_wye_um));
  t.add_column("r1x_um", flat(r.r1x_um));
  t.add_column("r2x_um", flat(r.r2x_um));
  t.add_column("r3y_um", flat(r.r3y_um));
  t.add_column("r4y_um", flat(r.r4y_um));
  if (r.u_w_um.size()) {
    t.set_meta("uncertainty",
               "u_*: standard uncertainty (k = 1) of each value in the gauge, from the joint "
               "system's covariance with sigma_hat of the redundant reference readings" +
                   std::string(" and the traverse's u"));
    t.set_meta("sigma_reference_um", std::to_string(r.sigma_reference_um) + " (dof " +
                                         std::to_string(r.dof_reference) + ")");
    t.set_meta("sigma_workpiece_um",
               std::to_string(r.sigma_workpiece_um) + " (" + r.sigma_workpiece_source + ")");
    for (const auto& [n, m] :
         {std::pair{"u_w_um", &r.u_w_um}, std::pair{"u_m_w_um", &r.u_m_w_um},
          std::pair{"u_m1x_um", &r.u_m1x_um}, std::pair{"u_m2x_um", &r.u_m2x_um},
          std::pair{"u_m3y_um", &r.u_m3y_um}, std::pair{"u_m4y_um", &r.u_m4y_um},
          std::pair{"u_m_wxe_um", &r.u_m_wxe_um}, std::pair{"u_m_wye_um", &r.u_m_wye_um},
          std::pair{"u_r1x_um", &r.u_r1x_um}, std::pair{"u_r2x_um", &r.u_r2x_um},
          std::pair{"u_r3y_um", &r.u_r3y_um}, std::pair{"u_r4y_um", &r.u_r4y_um}})
      t.add_column(n, flat(*m));
  }
  return t;
}

CsvTable three_point_profile_csv(double x0_mm, double dx_mm, const core::ThreePointResult& r) {
  CsvTable t;
  t.set_meta("errsep", "generalised three-point method, profile (datum f_0 = f_{N-1} = 0)");
  std::vector<double> x, f;
  for (Eigen::Index k = 0; k < r.f_um.size(); ++k) {
    x.push_back(x0_mm + k * dx_mm);
    f.push_back(r.f_um(k));
  }
  t.add_column("x_mm", x);
  t.add_column("f_um", f);
  return t;
}

CsvTable three_point_motion_csv(const Eigen::VectorXd& x_mm, const core::ThreePointResult& r) {
  CsvTable t;
  t.set_meta("errsep", "generalised three-point method, slide motion");
  t.add_column("x_mm", std::vector<double>(x_mm.data(), x_mm.data() + x_mm.size()));
  t.add_column("S_um", std::vector<double>(r.S_um.data(), r.S_um.data() + r.S_um.size()));
  std::vector<double> g;
  for (Eigen::Index k = 0; k < r.gamma_rad.size(); ++k)
    g.push_back(1e6 * r.gamma_rad(k));
  t.add_column("gamma_urad", g);
  return t;
}

}  // namespace errsep::io

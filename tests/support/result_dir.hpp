#pragma once
// Writes result directories in the formats errsep-separate / errsep-simulate --out produce
// (motion.csv, reference.csv, lcurve.csv, residuals.csv, refine_steps.csv) and a
// displacement-method grid CSV, from closed-form profiles, so the report tests do not depend on the
// solvers.
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "errsep/io/csv.hpp"
#include "errsep/io/refine_report.hpp"

namespace errsep::test {

struct ResultDirSpec {
  double dx_mm = 5, travel_mm = 305, reference_mm = 340;  // Zhao 2019 section 3
  std::function<double(double)> S_um;                     ///< straightness, default Zhao Eq. (21)
  std::function<double(double)> gamma_deg;                ///< tilt in degrees, default Eq. (22)
  std::function<double(double)> f_um;                     ///< reference profile, default Eq. (23)
  double u_S_um = 0.15, u_gamma_urad = 2.0, u_f_um = 0.1;
  std::string source = "/data/scans/simulated-demo-scan.csv";
  bool lcurve = true, residuals = true, refine = true;
  /// With refine: the refine table's u_S_unbounded0 line (io::refine_csv); empty: none.
  std::string refine_unbounded;
  /// With refine: the table's refine_role (service/refine_run.cpp).
  io::RefineRole refine_role = io::RefineRole::result;
  /// motion.csv's extra metadata (key, value), e.g. a scan sequence result's.
  std::vector<std::pair<std::string, std::string>> motion_metadata;
};

inline void write_four_sensor_result(const std::filesystem::path& dir, ResultDirSpec spec = {}) {
  constexpr double pi = 3.14159265358979323846;
  const double L = spec.travel_mm, L0 = spec.reference_mm;
  if (!spec.S_um)
    spec.S_um = [L](double x) {
      return 8.075 * std::sin(4 * pi / L * x) + 5.7 * std::sin(6 * pi / L * x + 5 * pi / 18) -
             1.9 * std::sin(14 * pi / L * x + pi / 2);
    };
  if (!spec.gamma_deg)
    spec.gamma_deg = [L](double x) {
      return 0.008 * std::sin(2 * pi / L * x + pi / 3) - 0.014 * std::sin(4 * pi / L * x + pi / 4) +
             0.005 * std::sin(10 * pi / L * x + 7 * pi / 12);
    };
  if (!spec.f_um) spec.f_um = [L0](double x) { return 5 * std::sin(10 * pi / L0 * x); };
  std::filesystem::create_directories(dir);
  const auto p = static_cast<std::size_t>(std::llround(L / spec.dx_mm)) + 1;
  std::vector<double> x, s, gd, gu, us, ug;
  for (std::size_t i = 0; i < p; ++i) {
    const double xi = spec.dx_mm * static_cast<double>(i);
    x.push_back(xi);
    s.push_back(spec.S_um(xi));
    gd.push_back(spec.gamma_deg(xi));
    gu.push_back(spec.gamma_deg(xi) * pi / 180 * 1e6);
    us.push_back(spec.u_S_um);
    ug.push_back(spec.u_gamma_urad);
  }
  io::CsvTable m;
  m.set_meta("method", "four-sensor");
  m.set_meta("lambda", "0.0123");
  m.set_meta("source", spec.source);
  m.set_meta("axis", "X");
  m.set_meta("straightness_direction", "Y");
  for (const auto& [k, v] : spec.motion_metadata)
    m.set_meta(k, v);
  m.add_column("x_mm", x);
  m.add_column("S_um", s);
  m.add_column("gamma_deg", gd);
  m.add_column("gamma_urad", gu);
  m.add_column("u_S_um", us);
  m.add_column("u_gamma_urad", ug);
  io::write_csv(dir / "motion.csv", m, 15);

  const auto n = static_cast<std::size_t>(std::llround(L0 / spec.dx_mm)) + 1;
  std::vector<double> fx, f, uf;
  for (std::size_t i = 0; i < n; ++i) {
    const double xi = spec.dx_mm * static_cast<double>(i);
    fx.push_back(xi);
    f.push_back(spec.f_um(xi));
    uf.push_back(spec.u_f_um);
  }
  io::CsvTable r;
  r.add_column("x_mm", fx);
  r.add_column("f_um", f);
  r.add_column("u_f_um", uf);
  io::write_csv(dir / "reference.csv", r, 15);

  if (spec.lcurve) {
    io::CsvTable l;
    l.set_meta("lambda_chosen", "0.0123");
    l.set_meta("lambda_rule", "lcurve");
    std::vector<double> lam, rn, sn, cu;
    for (int k = 0; k < 50; ++k) {
      const double v = std::pow(10.0, -5 + 0.12 * k);
      lam.push_back(v);
      rn.push_back(0.4 + 20 * v);  // a smooth L shape
      sn.push_back(1 + 80 / (1 + 300 * v));
      cu.push_back(0);
    }
    l.add_column("lambda", lam);
    l.add_column("residual_norm", rn);
    l.add_column("solution_norm", sn);
    l.add_column("curvature", cu);
    io::write_csv(dir / "lcurve.csv", l);
  }
  if (spec.residuals) {
    std::mt19937 rng(1);
    std::normal_distribution<double> nd(0, 0.1);
    std::vector<double> rx, rc, rr;
    for (int c = 1; c <= 4; ++c)
      for (double xi : x)
        rx.push_back(xi), rc.push_back(c), rr.push_back(nd(rng));
    io::CsvTable t;
    t.add_column("x_mm", rx);
    t.add_column("config", rc);
    t.add_column("residual_um", rr);
    io::write_csv(dir / "residuals.csv", t);
  }
  if (spec.refine) {
    // A refine step table as io::refine_csv writes it (errsep-refine): the base step, then a gain
    // step with three parameters; no truth (errors nan).
    io::CsvTable t;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    t.set_meta("format", "errsep refine steps");
    t.set_meta("model", "zhao2019-eq1+gain");
    t.set_meta("stop_reason", "no significant candidate");
    t.set_meta("residual_white", "true");
    t.set_meta("model_complete", "true");
    t.set_meta("lambda_before", "0.02 (reml)");
    t.set_meta("lambda_after", "0.0123 (reml)");
    t.set_meta("step0_effect", "zhao2019-eq1");
    t.set_meta("step1_effect", "gain");
    t.set_meta("step1_verdict", "applied: the gain changes S by 0.4 um");
    if (!spec.refine_unbounded.empty()) t.set_meta("u_S_unbounded0", spec.refine_unbounded);
    t.set_meta(io::kRefineRoleKey, io::to_string(spec.refine_role));
    for (int j = 0; j < 3; ++j)
      t.set_meta("step1_parameter" + std::to_string(j), "g" + std::to_string(j + 2));
    t.columns = io::refine_csv_columns();
    t.rows.push_back(
        {0, nan, nan, nan, nan, nan, nan, 0.31, 0.001, nan, nan, nan, nan, nan, nan, nan});
    for (int j = 0; j < 3; ++j)
      t.rows.push_back({1, double(j), j == 1 ? 0.05 : 0.001, 0.002, 212.0, 1e-9, 0.31, 0.26, 0.4,
                        nan, nan, nan, nan, nan, nan, 1});
    io::write_csv(dir / "refine_steps.csv", t);
  }
}

/// Two-axis grid x_mm, y_mm, w_um, m_w_um (x fastest), nx * ny nodes with spacing d_mm; with
/// m2x / m4y also the motion errors of the two tables (m2x_um, m4y_um, as errsep's two-axis
/// displacement result).
inline void write_grid_csv(const std::filesystem::path& file, std::size_t nx, std::size_t ny,
                           double d_mm, const std::function<double(double, double)>& w,
                           const std::function<double(double, double)>& m,
                           const std::function<double(double, double)>& m2x = {},
                           const std::function<double(double, double)>& m4y = {}) {
  std::vector<double> x, y, wv, mv, m2, m4;
  for (std::size_t j = 0; j < ny; ++j)
    for (std::size_t i = 0; i < nx; ++i) {
      const double xi = d_mm * static_cast<double>(i), yj = d_mm * static_cast<double>(j);
      x.push_back(xi);
      y.push_back(yj);
      wv.push_back(w(xi, yj));
      mv.push_back(m(xi, yj));
      if (m2x) m2.push_back(m2x(xi, yj));
      if (m4y) m4.push_back(m4y(xi, yj));
    }
  io::CsvTable t;
  t.set_meta("source", "/data/scans/simulated-two-axis.csv");
  t.add_column("x_mm", x);
  t.add_column("y_mm", y);
  t.add_column("w_um", wv);
  t.add_column("m_w_um", mv);
  if (m2x) t.add_column("m2x_um", m2);
  if (m4y) t.add_column("m4y_um", m4);
  io::write_csv(file, t, 15);
}

}  // namespace errsep::test

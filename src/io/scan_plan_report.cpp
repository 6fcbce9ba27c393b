#include "errsep/io/scan_plan_report.hpp"

#include <cstdio>
#include <sstream>

#include "errsep/io/atomic_file.hpp"
#include "errsep/version.hpp"

namespace errsep::io {
namespace {

std::string full(double v) {
  std::ostringstream os;
  os.precision(10);
  os << v;
  return os.str();
}

// Two significant figures, as GUM asks of an uncertainty.
std::string two(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.2g", v);
  return b;
}

std::vector<double> vec(const Eigen::VectorXd& v) {
  return {v.data(), v.data() + v.size()};
}

Series series(const std::string& title, const Eigen::VectorXd& x, const Eigen::VectorXd& y) {
  Series s;
  s.title = title;
  s.x = vec(x);
  s.y = vec(y);
  return s;
}

std::string spacings(const core::FourSensorConfig& c) {
  return "(" + std::to_string(c.s2) + ", " + std::to_string(c.s3) + ", " + std::to_string(c.s4) +
         ")";
}

std::string offsets(const core::FourSensorConfig& c, double origin) {
  const auto O = c.offsets_mm();
  std::string s;
  for (const double o : O)
    s += (s.empty() ? "" : ", ") + full(origin + o);
  return s;
}

constexpr const char* kDefinition =
    "U = k*sqrt(2*mean_x u_d(x)^2), u_d the standard uncertainty of S about its least-squares "
    "line: the rms over all pairs of positions that may hold the extremes";

}  // namespace

std::string scan_plan_toml(const core::ScanPlan& plan, bool with_origin) {
  const core::ScanPlanCandidate& c = plan.chosen;
  std::ostringstream os;
  os << "# errsep-plan " << kVersion
     << ": predicted straightness U = " << two(plan.prediction.expanded_um)
     << " um (k = " << full(plan.prediction.coverage_factor)
     << "), max u_S = " << two(plan.prediction.u_S_um.maxCoeff()) << " um at sigma "
     << full(plan.prediction.sigma_sample_um) << " um per sample\n";
  os << "# sensor stage offsets " << offsets(c.config, with_origin ? c.stage_origin_mm : 0.0)
     << " mm; reference length " << full(c.config.reference_length_mm()) << " mm\n";
  os << "[scan]\n";
  os << "dx_mm = " << full(c.config.dx_mm) << "\n";
  os << "s2 = " << c.config.s2 << "\n";
  os << "s3 = " << c.config.s3 << "\n";
  os << "s4 = " << c.config.s4 << "\n";
  os << "N = " << c.config.N << "\n";
  os << "averages = " << c.averages << "\n";
  if (with_origin) os << "sensor_stage_origin_mm = " << full(c.stage_origin_mm) << "\n";
  return os.str();
}

std::string scan_plan_summary(const core::ScanPlan& plan) {
  const core::ScanPlanCandidate& c = plan.chosen;
  const core::ScanPrediction& p = plan.prediction;
  std::ostringstream os;
  os << "four-sensor scan plan";
  if (plan.target_U_um > 0)
    os << " for a straightness U <= " << full(plan.target_U_um)
       << " um (k = " << full(p.coverage_factor) << ")";
  os << ": target " << (plan.target_met ? "met" : "NOT met") << "\n";
  os << "configuration: spacings " << spacings(c.config) << ", dx " << full(c.config.dx_mm)
     << " mm, N " << c.config.N << ", " << c.config.positions() << " slide positions over "
     << full(c.config.travel_mm()) << " mm, reference length "
     << full(c.config.reference_length_mm()) << " mm\n";
  os << "sensor stage offsets: " << offsets(c.config, 0.0) << " mm";
  if (c.stage_origin_mm != 0.0) os << " (configuration 1 at " << full(c.stage_origin_mm) << " mm)";
  os << "\n";
  os << "averages K " << c.averages << " (sigma " << full(p.sigma_sample_um) << " um per sample, "
     << two(p.sigma_um) << " um per averaged reading), " << c.readings << " readings\n";
  os << "predicted: straightness U " << two(p.expanded_um) << " um, max u_S "
     << two(p.u_S_um.maxCoeff()) << " um, U for extremes at the two worst points "
     << two(p.expanded_bound_um) << " um\n";
  os << "  (" << kDefinition << ")\n";
  if (plan.baseline.x_mm.size() > 0)
    os << "spacings (1, 1, 5) at the same dx and K: U " << two(plan.baseline.expanded_um)
       << " um, max u_S " << two(plan.baseline.u_S_um.maxCoeff()) << " um; ratio "
       << two(p.expanded_um / plan.baseline.expanded_um) << "\n";
  for (const auto& r : plan.runners_up)
    os << "runner-up: spacings " << spacings(r.config) << ", dx " << full(r.config.dx_mm)
       << " mm, K " << r.averages << ", U " << two(r.expanded_um) << " um, " << r.readings
       << " readings\n";
  for (const auto& n : plan.notes)
    os << n << "\n";
  os << "prediction of the unregularised separation, independent noise on every sample; the "
        "default estimator's smoothness prior on the reference can only tighten it (at the same "
        "sigma)\n";
  return os.str();
}

CsvTable scan_plan_table(const core::ScanPlan& plan) {
  const core::ScanPlanCandidate& c = plan.chosen;
  const core::ScanPrediction& p = plan.prediction;
  CsvTable t;
  t.set_meta("errsep", kVersion);
  t.set_meta("kind", "four-sensor scan plan (predicted before measuring)");
  t.set_meta("dx_mm", full(c.config.dx_mm));
  t.set_meta("s2", std::to_string(c.config.s2));
  t.set_meta("s3", std::to_string(c.config.s3));
  t.set_meta("s4", std::to_string(c.config.s4));
  t.set_meta("N", std::to_string(c.config.N));
  t.set_meta("averages", std::to_string(c.averages));
  t.set_meta("sensor_stage_origin_mm", full(c.stage_origin_mm));
  t.set_meta("sigma_sample_um", full(p.sigma_sample_um));
  t.set_meta("sigma_um", full(p.sigma_um));
  t.set_meta("coverage_factor", full(p.coverage_factor));
  t.set_meta("predicted_U_um", full(p.expanded_um));
  t.set_meta("predicted_U_bound_um", full(p.expanded_bound_um));
  t.set_meta("U_definition", kDefinition);
  t.set_meta("target_U_um", full(plan.target_U_um));
  t.set_meta("target_met", plan.target_met ? "true" : "false");
  if (plan.baseline.x_mm.size() > 0) t.set_meta("baseline_U_um", full(plan.baseline.expanded_um));
  t.set_meta("units", "x in mm, standard uncertainties (k = 1) in um");
  t.add_column("x_mm", vec(p.x_mm));
  t.add_column("u_S_um", vec(p.u_S_um));
  t.add_column("u_deviation_um", vec(p.u_deviation_um));
  if (plan.baseline.x_mm.size() == p.x_mm.size())
    t.add_column("u_S_baseline_um", vec(plan.baseline.u_S_um));
  return t;
}

LinePlot scan_plan_plot(const core::ScanPlan& plan) {
  const core::ScanPrediction& p = plan.prediction;
  LinePlot lp;
  lp.name = "u_S";
  lp.title = "predicted u_S(x), spacings " + spacings(p.config) +
             ", K = " + std::to_string(p.averages) + ", U = " + two(p.expanded_um) + " um";
  lp.xlabel = "x (mm)";
  lp.ylabel = "standard uncertainty (um)";
  lp.log_y = true;
  lp.series.push_back(series("u_S, spacings " + spacings(p.config), p.x_mm, p.u_S_um));
  lp.series.push_back(series("u of S about its least-squares line", p.x_mm, p.u_deviation_um));
  if (plan.baseline.x_mm.size() > 0)
    lp.series.push_back(
        series("u_S, spacings (1, 1, 5), same dx and K", plan.baseline.x_mm, plan.baseline.u_S_um));
  return lp;
}

ScanPlanFiles write_scan_plan(const core::ScanPlan& plan, const std::filesystem::path& dir,
                              bool with_origin, const std::optional<PlotOptions>& plot) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec)
    throw std::runtime_error(dir.string() +
                             ": cannot create the output directory: " + ec.message());
  ScanPlanFiles f;
  f.csv = dir / "plan.csv";
  f.toml = dir / "scan.toml";
  f.summary = dir / "plan.txt";
  write_csv(f.csv, scan_plan_table(plan));
  write_file_atomic(f.toml, scan_plan_toml(plan, with_origin));
  write_file_atomic(f.summary, scan_plan_summary(plan));
  if (plot) f.plot = render_line_plot(scan_plan_plot(plan), dir, *plot);
  return f;
}

}  // namespace errsep::io

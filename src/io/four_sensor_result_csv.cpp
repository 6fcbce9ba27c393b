#include "errsep/io/four_sensor_result_csv.hpp"

#include <sstream>
#include <stdexcept>

#include "errsep/core/four_sensor_evaluation.hpp"
#include "errsep/core/four_sensor_model.hpp"
#include "errsep/io/atomic_file.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/machine_axes_metadata.hpp"
#include "errsep/version.hpp"

namespace errsep::io {
namespace {

std::string fmt(double v) {
  std::ostringstream os;
  os.precision(10);
  os << v;
  return os.str();
}

std::vector<double> vec(const Eigen::VectorXd& v) {
  return {v.data(), v.data() + v.size()};
}

void common_meta(CsvTable& t, const core::FourSensorResult& r, const ResultWriteInfo& info) {
  t.set_meta("errsep", kVersion);
  t.set_meta("method", "four-sensor");
  t.set_meta("source", info.source);
  t.set_meta("axis", info.axis);
  t.set_meta("straightness_direction", info.straightness_direction);
  t.set_meta("dx_mm", fmt(r.config.dx_mm));
  t.set_meta("s2", std::to_string(r.config.s2));
  t.set_meta("s3", std::to_string(r.config.s3));
  t.set_meta("s4", std::to_string(r.config.s4));
  t.set_meta("N", std::to_string(r.config.N));
  t.set_meta("estimator", info.estimator.empty() ? core::to_string(r.estimator) : info.estimator);
  t.set_meta("prior", core::to_string(r.penalty));
  t.set_meta("lambda", fmt(r.lambda));
  t.set_meta("lambda_rule", core::to_string(r.rule));
  t.set_meta("lambda_fallback", core::to_string(r.lambda_fallback));
  t.set_meta("edf_f", fmt(r.edf_f));
  t.set_meta("sigma_hat_um", fmt(r.sigma_um));
  // σ̂'s degrees of freedom: a user sizing a simultaneous band (or a t-based k) needs them.
  t.set_meta("sigma_hat_dof", std::to_string(r.redundancy_dof));
  t.set_meta("uncertainty_model",
             !info.uncertainty_model.empty() ? info.uncertainty_model
             : r.covariance
                 ? "posterior covariance of the separation (prior included), sigma from "
                   "the redundant readings"
                 : "covariance of the estimate at its lambda (shrinkage bias not included)");
  if (!r.determination_note.empty()) t.set_meta("not_determined", r.determination_note);
  for (const auto& [k, v] : info.extra_metadata)
    t.set_meta(k, v);
}

}  // namespace

void carry_machine_axes(const std::vector<std::pair<std::string, std::string>>& raw_metadata,
                        ResultWriteInfo& info) {
  const auto axes = machine_axes_from_metadata(raw_metadata);
  if (!axes) return;
  info.axis = std::string(1, axes->input_axis);
  info.straightness_direction = std::string(1, axes->output_axis);
  for (auto& kv : machine_axes_metadata(*axes))
    info.extra_metadata.push_back(std::move(kv));
}

void write_four_sensor_result(const std::filesystem::path& dir, const core::FourSensorResult& r,
                              const ResultWriteInfo& info) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw std::runtime_error("cannot create '" + dir.string() + "': " + ec.message());
  const auto P = r.S_um.size();
  const Eigen::VectorXd zeroP = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(P));

  CsvTable motion;
  common_meta(motion, r, info);
  motion.set_meta("units", "x in mm, S in um, gamma in deg and urad, u = standard uncertainty k=1");
  motion.set_meta("gamma_note", "gamma up to the constant e4/(D2+D3+D4) (Zhao 2019 Eq. 19)");
  motion.add_column("x_mm", vec(r.x_mm));
  motion.add_column("S_um", vec(r.S_um));
  motion.add_column("gamma_deg", vec(r.gamma_rad * core::kDegPerRad));
  motion.add_column("gamma_urad", vec(r.gamma_rad * 1e6));
  motion.add_column("u_S_um", vec(r.u_S_um.size() == r.S_um.size() ? r.u_S_um : zeroP));
  motion.add_column("u_gamma_urad",
                    vec(r.u_gamma_rad.size() == r.S_um.size() ? r.u_gamma_rad * 1e6 : zeroP));
  // ISO 230-1 straightness with U from the separation's covariance (the report takes these).
  if (r.covariance && P >= 2)
    for (const auto ref : {core::ReferenceLine::end_points, core::ReferenceLine::least_squares,
                           core::ReferenceLine::minimum_zone}) {
      const auto e = core::four_sensor_straightness(r, ref);
      const std::string key = std::string("straightness_") + core::to_string(ref);
      motion.set_meta(key + "_um", fmt(e.straightness_um));
      motion.set_meta(key + "_U_um", fmt(e.expanded_um));
      motion.set_meta(key + "_bias_um", fmt(e.bias_um));
      motion.set_meta(key + "_of_estimate_um", fmt(e.zone.straightness_um));
    }
  for (const auto& [k, v] : info.motion_metadata)
    motion.set_meta(k, v);

  CsvTable ref;
  common_meta(ref, r, info);
  ref.set_meta("units", "x in mm, f in um");
  ref.set_meta("gauge", core::to_string(r.gauge));
  ref.add_column("x_mm", vec(r.f_x_mm));
  ref.add_column("f_um", vec(r.f_um));
  ref.add_column(
      "u_f_um",
      vec(r.u_f_um.size() == r.f_um.size() ? r.u_f_um : Eigen::VectorXd::Zero(r.f_um.size())));

  CsvTable lc;
  common_meta(lc, r, info);
  lc.set_meta("lambda_chosen", fmt(r.lambda));
  lc.set_meta("corner_at_edge", r.lcurve.at_edge ? "true" : "false");
  lc.set_meta("corner_branch_decades", fmt(r.lcurve.branch_decades));
  lc.set_meta("lambda_fallback", core::to_string(r.lambda_fallback));
  std::vector<double> l, rn, sn, k;
  for (const auto& p : r.lcurve.points) {
    l.push_back(p.lambda);
    rn.push_back(p.residual_norm);
    sn.push_back(p.solution_norm);
    k.push_back(p.curvature);
  }
  if (!r.lambda_grid.empty() && r.lambda_grid.size() == r.lambda_criterion.size()) {
    // Rules reml and gcv: the search's grid and the criterion it minimised (no L-curve drawn).
    lc.set_meta("curve", std::string("the lambda search of rule ") + core::to_string(r.rule));
    lc.columns = {"lambda", std::string(core::to_string(r.rule)) + "_criterion"};
    for (std::size_t i = 0; i < r.lambda_grid.size(); ++i)
      lc.rows.push_back({r.lambda_grid[i], r.lambda_criterion[i]});
  } else {
    lc.columns = {"lambda", "residual_norm", "solution_norm", "curvature"};
    for (std::size_t i = 0; i < l.size(); ++i)
      lc.rows.push_back({l[i], rn[i], sn[i], k[i]});
  }

  CsvTable res;
  common_meta(res, r, info);
  if (const auto& tr = info.traverses) {
    // Every traverse of a scan sequence, in the order measured (a hysteresis or a drift shows
    // between traverses of one configuration, not in its first traverse alone).
    const Eigen::Index T = tr->residual_um.cols();
    if (tr->residual_um.rows() != r.x_mm.size() || tr->t_s.rows() != tr->residual_um.rows() ||
        tr->t_s.cols() != T || static_cast<Eigen::Index>(tr->configuration.size()) != T ||
        static_cast<Eigen::Index>(tr->direction.size()) != T)
      throw std::invalid_argument("write_four_sensor_result: traverse residuals are not P x T");
    res.set_meta("units",
                 "x in mm, t in s, residual in um; traverse 1..T in the order measured, config "
                 "1..4, direction +1 forward, -1 backward");
    res.set_meta("traverses", std::to_string(T));
    res.columns = {"x_mm", "traverse", "config", "direction", "t_s", "residual_um"};
    for (Eigen::Index j = 0; j < T; ++j)
      for (Eigen::Index n = 0; n < tr->residual_um.rows(); ++n)
        res.rows.push_back({r.x_mm(n), static_cast<double>(j + 1),
                            static_cast<double>(tr->configuration[static_cast<std::size_t>(j)]),
                            static_cast<double>(tr->direction[static_cast<std::size_t>(j)]),
                            tr->t_s(n, j), tr->residual_um(n, j)});
  } else {
    res.set_meta("units", "x in mm, residual in um; config 1..4");
    res.columns = {"x_mm", "config", "residual_um"};
    for (Eigen::Index n = 0; n < r.sensor_residual_um.rows(); ++n)
      for (int j = 0; j < 4; ++j)
        res.rows.push_back({r.x_mm(n), static_cast<double>(j + 1), r.sensor_residual_um(n, j)});
  }

  std::ostringstream summary;
  summary << (info.title.empty() ? r.brief_report() : info.title) << "\n"
          << "source: " << info.source << "\n"
          << "identifiability: the constant and linear parts of f are fixed by f(x_0) = "
             "f(x_{N-1}) = 0 (Eq. 11); its quadratic part by the assumption that "
          << (r.gauge == core::CurvatureGauge::reference_without_curvature
                  ? "the reference surface has no bow (f orthogonal to t(1-t)), imposed exactly"
              : r.gauge == core::CurvatureGauge::sensor_stage_without_curvature
                  ? "the sensor stage's zero-adjustment values have no quadratic component in the "
                    "sensor position (a weak row in place of Eq. 12)"
                  : "Eq. (12) holds as printed")
          << "; gamma is reported up to the constant e4/(D2+D3+D4).\n"
          << "lambda: " << core::to_string(r.rule) << ", L-curve branch " << r.lcurve.branch_decades
          << " decades, fallback " << core::to_string(r.lambda_fallback) << "\n";
  if (!r.determination_note.empty()) summary << "not determined: " << r.determination_note << "\n";
  for (const auto& line : info.summary_notes)
    summary << line << "\n";

  write_csv(dir / "motion.csv", motion);
  write_csv(dir / "reference.csv", ref);
  write_csv(dir / "lcurve.csv", lc);
  write_csv(dir / "residuals.csv", res);
  write_file_atomic(dir / "summary.txt", summary.str());
}

}  // namespace errsep::io

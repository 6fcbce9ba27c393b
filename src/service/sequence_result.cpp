#include "errsep/service/sequence_result.hpp"

#include <cmath>
#include <cstdio>
#include <string>
#include <utility>

#include "errsep/core/iso230.hpp"
#include "errsep/io/csv.hpp"

namespace errsep::service {

bool sequence_is_the_result(const core::ScanSequence& seq) {
  return seq.redundant() || seq.name != core::to_string(core::ScanSequenceKind::single);
}

core::FourSensorResult sequence_as_result(const core::FourSensorResult& single,
                                          const core::ScanSequence& seq,
                                          const core::SequenceRefineResult& sr) {
  const core::SequenceFit& fit = sr.after;
  core::FourSensorResult r;
  r.config = single.config;
  r.x_mm = single.x_mm;
  r.f_x_mm = single.f_x_mm;
  r.S_um = fit.S_um;
  r.gamma_rad = fit.gamma_rad;
  r.f_um = fit.f_um;
  r.u_S_um = fit.u_S_in_gauge_um();
  r.u_gamma_rad = fit.u_gamma_in_gauge_rad();  // γ is stated in the fit's gauge (e_4 = 0)
  r.u_f_um = fit.u_f_um;
  r.sensor_residual_um.resize(fit.residual_um.rows(), 4);
  for (int c = 0; c < 4; ++c)
    for (int k = 0; k < seq.size(); ++k)
      if (seq.traverses[static_cast<std::size_t>(k)].configuration == c) {
        r.sensor_residual_um.col(c) = fit.residual_um.col(k);
        r.e_um(c) = fit.e_um(k);
        break;
      }
  r.lambda = 0.0;
  r.rule = core::LambdaRule::least_squares;
  r.estimator = single.estimator;
  r.penalty = core::Penalty::none;
  r.gauge = core::CurvatureGauge::reference_without_curvature;
  r.sigma_um = fit.sigma_um;
  r.redundancy_dof = fit.dof;
  r.edf = static_cast<double>(fit.residual_um.size() - fit.dof);
  r.residual_norm = std::sqrt(fit.rss_um2);
  return r;
}

void describe_sequence_result(const core::FourSensorConfig& cfg, const core::ScanSequence& seq,
                              const core::SequenceRefineResult& sr, const Eigen::VectorXd& x_mm,
                              io::ResultWriteInfo& info) {
  std::string added;
  for (const auto& a : sr.added)
    added += (added.empty() ? "" : ", ") + std::string(core::to_string(a.kind));
  const std::string what =
      "scan sequence fit (plan: " + seq.name + ", " + std::to_string(seq.size()) +
      " traverses, least squares), effects applied: " + (added.empty() ? "none" : added);
  {
    // summary.txt's first line names the fit (brief_report() would say "least_squares").
    const core::FourSensorConfig& g = cfg;
    char title[512];
    std::snprintf(title, sizeof title,
                  "four-sensor scan sequence fit N=%d P=%d s=(%d,%d,%d) dx=%.4g mm: plan %s, "
                  "%d traverses, every reading in one unregularised least-squares fit (Eq. 1 "
                  "per traverse, own zero adjustment each), effects applied: %s%s, "
                  "sigma_hat=%.3g um (dof %d)",
                  g.N, g.positions(), g.s2, g.s3, g.s4, g.dx_mm, seq.name.c_str(), seq.size(),
                  added.empty() ? "none" : added.c_str(),
                  sr.knock.fitted && sr.knock.applied ? ", knocked sensor removed" : "",
                  sr.after.sigma_um, sr.after.dof);
    info.title = title;
    // residuals.csv: every traverse, with its direction and time.
    io::ResultWriteInfo::TraverseResiduals tr;
    tr.residual_um = sr.after.residual_um;
    tr.t_s = seq.times_s(g);
    for (const auto& t : seq.traverses) {
      tr.configuration.push_back(t.configuration + 1);
      tr.direction.push_back(static_cast<int>(core::direction_sign(t.direction)));
    }
    info.traverses = std::move(tr);
  }
  info.estimator = "scan_sequence_fit";
  info.uncertainty_model =
      "covariance of the unregularised least-squares fit of every traverse (no prior, no "
      "shrinkage), sigma from its residual; applied effects' parameters and tau included, "
      "widened by what effects detected but not identifiable from the plan could do to S";
  info.extra_metadata.emplace_back("scan_plan", seq.name);
  info.extra_metadata.emplace_back("separation", what);
  info.summary_notes.push_back("result: " + what + "; sigma_hat " +
                               io::format_number(sr.after.sigma_um) + " um (" +
                               std::to_string(sr.after.dof) + " dof)");
  if (sr.u_S_widening_um.size() && sr.u_S_widening_um.maxCoeff() > 0)
    info.summary_notes.push_back(
        "u_S includes what effects detected but not identifiable from this plan could do to "
        "S (see the findings)");
  for (const auto& line : sr.report)
    info.summary_notes.push_back("finding: " + line);
  // A term of u_S held at the readings' bound (core::SequenceRefineResult::unbounded, in the
  // findings above): motion.csv says so beside its u_S_um column, as a single scan's refine does.
  if (!sr.unbounded.empty()) info.extra_metadata.emplace_back("u_S_bounded_by_data", "false");
  // motion.csv's u_gamma_urad is in the fit's gauge (γ's constant set by e_4 = 0, Eq. 19); a
  // fitted warm-up of configuration 4 leaves that constant all but undetermined (u_γ thousands of
  // µrad, uniform) while γ's shape is as well determined as without it.  Both are stated, and
  // the case is said in words: γ's range and its deviation from a line hold, its level does not.
  const auto rms = [](const Eigen::VectorXd& v) {
    return v.size() ? std::sqrt(v.squaredNorm() / static_cast<double>(v.size())) : 0.0;
  };
  const double ug_shape_urad = 1e6 * rms(sr.after.u_gamma_rad);
  const double ug_gauge_urad = 1e6 * rms(sr.after.u_gamma_in_gauge_rad());
  info.motion_metadata.emplace_back(io::kMetaUGammaShapeUrad, io::format_number(ug_shape_urad));
  if (ug_gauge_urad > kGammaLevelUndeterminedRatio * ug_shape_urad) {
    info.extra_metadata.emplace_back(io::kMetaGammaLevelDetermined, "false");
    info.summary_notes.push_back(
        "gamma's level is not determined by this plan with the effects applied: u_gamma " +
        io::format_number(ug_gauge_urad) + " urad RMS in motion.csv's gauge (e4 = 0), " +
        io::format_number(ug_shape_urad) +
        " urad RMS about gamma's best-fit constant and line: its range and its deviation from a "
        "line hold, its absolute value does not");
  }
  // The angular deviation with U from the fit's covariance of γ: max − min cancels γ's constant,
  // which the report's pointwise propagation of u_gamma_urad (the gauge's) cannot.
  {
    const auto a = core::sequence_angular_deviation(sr.after);
    info.motion_metadata.emplace_back(io::kMetaAngularDeviationUrad,
                                      io::format_number(a.deviation_urad));
    info.motion_metadata.emplace_back(io::kMetaAngularDeviationUUrad,
                                      io::format_number(a.uncertainty.expanded));
  }
  // ISO 230-1 straightness with U from the fit's covariance (as the separation writes its
  // own from its posterior covariance).
  for (const auto ref : {core::ReferenceLine::end_points, core::ReferenceLine::least_squares,
                         core::ReferenceLine::minimum_zone}) {
    const auto e = core::sequence_straightness(sr.after, x_mm, ref);
    const std::string key = std::string("straightness_") + core::to_string(ref);
    info.motion_metadata.emplace_back(key + "_um", io::format_number(e.straightness_um));
    info.motion_metadata.emplace_back(key + "_U_um", io::format_number(e.expanded_um));
    info.motion_metadata.emplace_back(key + "_bias_um", io::format_number(e.bias_um));
    info.motion_metadata.emplace_back(key + "_of_estimate_um",
                                      io::format_number(e.zone.straightness_um));
  }
}

}  // namespace errsep::service

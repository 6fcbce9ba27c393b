#include "errsep/service/four_sensor_pipeline.hpp"

#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "errsep/core/four_sensor_system.hpp"

#include "errsep/io/csv.hpp"
#include "errsep/io/four_sensor_result_csv.hpp"
#include "errsep/io/refine_run.hpp"
#include "errsep/io/staged_directory.hpp"

namespace errsep::service {
namespace fs = std::filesystem;

bool FourSensorPipelineOptions::is_valid(std::string* why) const {
  if (!separation.is_valid(why)) return false;
  if (!(refine_alpha > 0.0 && refine_alpha < 1.0)) {
    if (why) *why = "refine_alpha = " + std::to_string(refine_alpha) + ": must be in (0, 1)";
    return false;
  }
  return true;
}

FourSensorPipelineOptions pipeline_options(const io::MachineConfig& cfg, const std::string& gauge) {
  // [separation] of the config; a gauge given here (the command line) over it.
  io::SeparationConfig sep = cfg.separation;
  if (!gauge.empty()) {
    const auto g = core::curvature_gauge_from_string(gauge);
    if (!g) throw std::invalid_argument("--gauge: unknown gauge '" + gauge + "'");
    sep.gauge = *g;
  }
  FourSensorPipelineOptions o;
  o.separation = sep.options();
  o.refine = cfg.refine.enabled;
  o.refine_alpha = cfg.refine.alpha;
  return o;
}

namespace {

// The result of a scan sequence's refined fit in the single separation's form (motion.csv and
// the rest are written from it): S, γ, f and their uncertainties in the fit's gauge (the same
// gauge as the default separation: f's ends at 0, f without bow), the residuals of each
// configuration's first traverse (residuals.csv holds one per configuration), λ = 0.
core::FourSensorResult result_of_sequence(const core::FourSensorResult& single,
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
  r.u_gamma_rad = fit.u_gamma_rad;
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

}  // namespace

FourSensorPipeline::FourSensorPipeline(FourSensorPipelineOptions opts) : opts_(std::move(opts)) {
  std::string why;
  if (!opts_.is_valid(&why)) throw std::invalid_argument("four-sensor pipeline: " + why);
}

FourSensorPipelineResult FourSensorPipeline::separate(const io::RawFourSensorScan& raw,
                                                      const fs::path& dir, const fs::path& raw_csv,
                                                      const std::string& source,
                                                      const std::string& run_id) const {
  if (!raw.geometry)
    throw std::invalid_argument(source + ": no scan geometry ('# dx_mm:', '# s2:' ... lines)");
  const auto P = static_cast<Eigen::Index>(raw.positions());
  Eigen::MatrixXd m(P, 4);
  for (Eigen::Index j = 0; j < 4; ++j)
    for (Eigen::Index n = 0; n < P; ++n)
      m(n, j) = raw.m_um[static_cast<std::size_t>(j)][static_cast<std::size_t>(n)];

  FourSensorPipelineResult out;
  out.separation = core::separate_four_sensor(*raw.geometry, m, opts_.separation);
  io::ResultWriteInfo info{source, "X", "Y", {{"run_id", run_id}}};
  io::carry_machine_axes(raw.metadata, info);  // where the scan ran, machine coordinates
  if (raw.sequence) {
    // A scan sequence: its fit of all traverses is the result (file comment).
    const auto [seq, m_seq] = io::scan_sequence_of(raw);
    if (seq.redundant() || seq.name != core::to_string(core::ScanSequenceKind::single)) {
      core::SequenceRefineOptions so;
      so.alpha = opts_.refine_alpha;
      out.sequence_refine = core::refine_four_sensor_sequence(*raw.geometry, seq, m_seq, so);
      const core::SequenceRefineResult& sr = *out.sequence_refine;
      out.single_scan = std::move(out.separation);
      out.separation = result_of_sequence(*out.single_scan, seq, sr);
      std::string added;
      for (const auto& a : sr.added)
        added += (added.empty() ? "" : ", ") + std::string(core::to_string(a.kind));
      const std::string what =
          "scan sequence fit (plan: " + seq.name + ", " + std::to_string(seq.size()) +
          " traverses, least squares), effects applied: " + (added.empty() ? "none" : added);
      {
        // summary.txt's first line names the fit (brief_report() would say "least_squares").
        const core::FourSensorConfig& g = *raw.geometry;
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
          tr.direction.push_back(t.direction == core::TraverseDirection::forward ? 1 : -1);
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
      for (const auto& line : sr.report) {
        info.summary_notes.push_back("finding: " + line);
        out.warnings.push_back("scan sequence (" + sr.plan + "): " + line);
      }
      // ISO 230-1 straightness with U from the fit's covariance (as the separation writes its
      // own from its posterior covariance).
      for (const auto ref : {core::ReferenceLine::end_points, core::ReferenceLine::least_squares,
                             core::ReferenceLine::minimum_zone}) {
        const auto e = core::sequence_straightness(sr.after, out.separation->x_mm, ref);
        const std::string key = std::string("straightness_") + core::to_string(ref);
        info.motion_metadata.emplace_back(key + "_um", io::format_number(e.straightness_um));
        info.motion_metadata.emplace_back(key + "_U_um", io::format_number(e.expanded_um));
        info.motion_metadata.emplace_back(key + "_bias_um", io::format_number(e.bias_um));
        info.motion_metadata.emplace_back(key + "_of_estimate_um",
                                          io::format_number(e.zone.straightness_um));
      }
    }
  }
  const core::FourSensorResult& res = *out.separation;
  io::write_four_sensor_result(dir, res, info);
  out.files = {"motion.csv", "reference.csv", "lcurve.csv", "residuals.csv", "summary.txt"};
  if (res.lambda_fallback == core::LambdaFallback::discrepancy)
    out.warnings.push_back(
        "the L-curve has no corner inside the lambda range; lambda was chosen by the discrepancy "
        "principle instead");
  else if (res.lambda_fallback == core::LambdaFallback::collapse_least_squares)
    out.warnings.push_back(res.determination_note);

  if (opts_.refine) {
    io::RefineRunOptions ro;  // the defaults of errsep-refine, the separation's options
    ro.refine.solve = opts_.separation;
    ro.refine.alpha = opts_.refine_alpha;
    ro.reference_csv = opts_.refine_reference;
    ro.source = source;
    // A set of its own inside the scan's (errsep-refine may replace it later).
    auto run = io::run_refine(raw_csv, dir / "refine", ro);
    if (!run.result.model_complete())
      out.warnings.push_back(
          "the refined model is incomplete (residual not white or implausible effects rejected): "
          "see refine/refine_report.txt");
    out.refine = std::move(run.result);
    out.files.push_back("refine/");
    // A sequence that is the result was refined above (its findings are in `warnings`);
    // run_refine makes the same refine.
    if (run.sequence && !out.sequence_refine) {
      for (const auto& line : run.sequence->report)
        out.warnings.push_back("scan sequence (" + run.sequence->plan + "): " + line);
      out.sequence_refine = std::move(run.sequence);
    }
  }
  return out;
}

FourSensorPipelineResult FourSensorPipeline::write_result_set(const io::RawFourSensorScan& raw_in,
                                                              const fs::path& out,
                                                              const std::string& writer) const {
  io::StagedDirectory stage(out, {"scan", writer, false, {}});
  io::RawFourSensorScan raw = raw_in;
  raw.metadata.emplace(raw.metadata.begin(), "run_id", stage.run_id());
  const fs::path raw_csv = stage.dir() / "raw.csv";
  io::write_raw_four_sensor_csv(raw_csv, raw);
  FourSensorPipelineResult res;
  try {
    res = separate(raw, stage.dir(), raw_csv, (out / "raw.csv").string(), stage.run_id());
  } catch (const std::exception& e) {
    // The measurements are kept: the set holds the raw file alone.
    for (const auto& entry : fs::directory_iterator(stage.dir()))
      if (entry.path().filename() != "raw.csv") fs::remove_all(entry.path());
    res = {};
    res.error = e.what();
  }
  res.files.insert(res.files.begin(), "raw.csv");
  stage.commit();
  return res;
}

}  // namespace errsep::service

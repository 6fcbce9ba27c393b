#include "errsep/service/four_sensor_pipeline.hpp"

#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "errsep/core/four_sensor_system.hpp"

#include "errsep/io/csv.hpp"
#include "errsep/io/four_sensor_result_csv.hpp"
#include "errsep/io/staged_directory.hpp"
#include "errsep/service/refine_run.hpp"
#include "errsep/service/sequence_result.hpp"

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
    if (sequence_is_the_result(seq)) {
      core::SequenceRefineOptions so;
      so.alpha = opts_.refine_alpha;
      out.sequence_refine = core::refine_four_sensor_sequence(*raw.geometry, seq, m_seq, so);
      ++out.sequence_refines;
      const core::SequenceRefineResult& sr = *out.sequence_refine;
      out.single_scan = std::move(out.separation);
      out.separation = sequence_as_result(*out.single_scan, seq, sr);
      describe_sequence_result(*raw.geometry, seq, sr, out.separation->x_mm, info);
      for (const auto& line : sr.report)
        out.warnings.push_back("scan sequence (" + sr.plan + "): " + line);
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
    RefineRunOptions ro;  // the defaults of errsep-refine, the separation's options
    ro.refine.solve = opts_.separation;
    ro.refine.alpha = opts_.refine_alpha;
    ro.reference_csv = opts_.refine_reference;
    ro.source = source;
    // The sequence refined above is taken, not made again (one refine per job).
    if (out.sequence_refine) ro.sequence_refine = &*out.sequence_refine;
    // A set of its own inside the scan's (errsep-refine may replace it later).
    auto run = run_refine(raw_csv, dir / "refine", ro);
    if (!run.result.model_complete())
      out.warnings.push_back(
          "the refined model is incomplete (residual not white or implausible effects rejected): "
          "see refine/refine_report.txt");
    out.refine = std::move(run.result);
    if (run.sequence && !run.sequence_taken) ++out.sequence_refines;
    out.files.push_back("refine/");
    // A sequence that is the result was refined above (its findings are in `warnings`) and
    // taken by run_refine; one that is not (a single plan) was refined there.
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

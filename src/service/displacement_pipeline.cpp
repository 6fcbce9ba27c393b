#include "errsep/service/displacement_pipeline.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "errsep/io/displacement_refine_csv.hpp"
#include "errsep/io/machine_axes_metadata.hpp"
#include "errsep/io/staged_directory.hpp"

namespace errsep::service {
namespace fs = std::filesystem;

namespace {

std::string fmt(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

bool same_axis(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  if (a.size() != b.size()) return false;
  for (Eigen::Index k = 0; k < a.size(); ++k)
    if (std::abs(a(k) - b(k)) > 1e-6 * std::max(1.0, std::abs(a(k)))) return false;
  return true;
}

/// The separation's options for a run, from the pipeline's and the file's (d, Δx).
core::DisplacementOptions separation_options(const DisplacementPipelineOptions& po,
                                             const io::OneAxisInput& in, const std::string& input) {
  core::DisplacementOptions o;
  o.sample_interval_mm = in.dx_mm;
  const auto& d = po.displacement_mm;
  if (d && in.d_mm && std::abs(*d - *in.d_mm) > 1e-9 * std::max(1.0, *d))
    throw std::invalid_argument(input + ": --d-mm " + std::to_string(*d) +
                                " contradicts the file's d_mm " + std::to_string(*in.d_mm));
  o.displacement_mm = d ? *d : in.d_mm.value_or(in.dx_mm);
  o.initial_um = po.initial_um;
  o.chain_join = po.chain_join;
  o.displacement_sigma_mm = po.displacement_sigma_mm;
  if (po.reading_sigma_um) o.reading_sigma_um = *po.reading_sigma_um;
  std::string why;
  if (!o.is_valid(&why)) throw std::invalid_argument(input + ": " + why);
  return o;
}

Eigen::VectorXd vector_of(const std::optional<std::vector<double>>& v) {
  if (!v) return {};
  return Eigen::Map<const Eigen::VectorXd>(v->data(), static_cast<Eigen::Index>(v->size()));
}

}  // namespace

bool DisplacementPipelineOptions::is_valid(std::string* why) const {
  const auto fail = [why](const std::string& w) {
    if (why) *why = w;
    return false;
  };
  if (displacement_mm && !(*displacement_mm > 0.0))
    return fail("displacement_mm = " + std::to_string(*displacement_mm) + ": must be > 0");
  if (!(displacement_sigma_mm >= 0.0) || !std::isfinite(displacement_sigma_mm))
    return fail("displacement_sigma_mm = " + std::to_string(displacement_sigma_mm) +
                ": must be finite and >= 0");
  if (reading_sigma_um && !(*reading_sigma_um > 0.0 && std::isfinite(*reading_sigma_um)))
    return fail("reading_sigma_um = " + std::to_string(*reading_sigma_um) +
                ": must be finite and > 0");
  if (!std::isfinite(initial_um)) return fail("initial_um: must be finite");
  std::string sub;
  if (!refine_options.is_valid(&sub)) return fail("refine_options." + sub);
  return residuals.is_valid(why);
}

std::string DisplacementPipelineResult::brief_report() const {
  if (!separation) return "displacement separation failed: " + error;
  const core::OneAxisJointResult& j = *separation;
  std::string s = j.estimate.brief_report() + "\n";
  s += j.u_w_um.size() ? "u(w) " + fmt(j.u_w_um.minCoeff()) + ".." + fmt(j.u_w_um.maxCoeff()) +
                             " um, sigma " + fmt(j.sigma_um) + " um (" + j.sigma_source + ")"
                       : "no uncertainty: " + j.sigma_source;
  s += "\ngauge: " + j.gauge + "\n" + residuals.brief_report();
  if (refine) s += "\n" + refine->brief_report();
  return s;
}

DisplacementPipelineOptions displacement_pipeline_options(const io::MachineConfig& cfg) {
  DisplacementPipelineOptions o;
  o.refine = cfg.refine.enabled;
  o.refine_options.alpha = cfg.refine.alpha;
  return o;
}

void set_residual_metadata(io::CsvTable& t, const core::DisplacementResiduals& r,
                           const std::string& residuals_file) {
  t.set_meta("residuals", residuals_file);
  std::string v = r.families.empty() ? std::string("nothing redundant to test")
                                     : (r.white ? std::string("white") : std::string("NOT white"));
  for (const auto& f : r.families)
    if (f.dof > 0)
      v += "; " + std::string(core::to_string(f.kind)) + " sigma_hat " + fmt(f.sigma_um) +
           " um (dof " + std::to_string(f.dof) + "), whiteness p " + fmt(f.whiteness.p_value);
  t.set_meta("residual_verdict", v);
}

DisplacementPipeline::DisplacementPipeline(DisplacementPipelineOptions opts)
    : opts_(std::move(opts)) {
  std::string why;
  if (!opts_.is_valid(&why)) throw std::invalid_argument("displacement pipeline: " + why);
}

DisplacementPipelineResult DisplacementPipeline::compute(const std::vector<io::OneAxisInput>& all,
                                                         const std::vector<std::string>& names,
                                                         const std::string& residuals_file) const {
  if (all.empty() || names.size() != all.size())
    throw std::invalid_argument("displacement pipeline: one name per run needed");
  const std::string& input = names.front();
  const io::OneAxisInput& in = all.front();
  for (std::size_t k = 1; k < all.size(); ++k) {
    const auto& a = all[k];
    if (!same_axis(a.x_mm, in.x_mm))
      throw std::invalid_argument(names[k] + ": the x positions differ from those of " + input +
                                  " (repeated runs must share the grid)");
    if (a.d_mm && in.d_mm && std::abs(*a.d_mm - *in.d_mm) > 1e-9 * std::max(1.0, *a.d_mm))
      throw std::invalid_argument(names[k] + ": d_mm " + std::to_string(*a.d_mm) +
                                  " differs from " + input + "'s " + std::to_string(*in.d_mm));
  }
  const core::DisplacementOptions o = separation_options(opts_, in, input);

  std::vector<core::OneAxisRun> runs;
  for (const auto& a : all)
    runs.push_back({a.s1_1_um, a.s2_1_um, a.s2_2_um, a.s1_2_um});
  const auto mean = core::mean_of_runs(runs);
  DisplacementPipelineResult out;
  out.separation =
      core::separate_displacement_joint(mean.s1_1_um, mean.s2_1_um, mean.s2_2_um, mean.s1_2_um, o);
  out.residuals = core::displacement_residuals_one_axis(in.x_mm, runs, opts_.residuals);
  out.profile = io::one_axis_result_csv(in.x_mm, *out.separation);
  if (runs.size() > 1) out.profile.set_meta("runs", std::to_string(runs.size()) + " (mean)");
  set_residual_metadata(out.profile, out.residuals, residuals_file);
  out.residual_table = io::displacement_residuals_csv(out.residuals, false);
  return out;
}

core::OneAxisRefineResult DisplacementPipeline::refine(const io::OneAxisInput& in,
                                                       const Eigen::VectorXd& t1_s,
                                                       const Eigen::VectorXd& t2_s,
                                                       const std::string& input) const {
  core::OneAxisRefineOptions ro = opts_.refine_options;
  ro.scan2_order = in.scan2_order;  // the plan the scan ran, for times it did not record
  return core::refine_one_axis(in.s1_1_um, in.s2_1_um, in.s2_2_um, in.s1_2_um, t1_s, t2_s,
                               separation_options(opts_, in, input), ro);
}

DisplacementPipelineResult DisplacementPipeline::separate(const fs::path& dir,
                                                          const fs::path& raw_csv,
                                                          const std::string& source,
                                                          const std::string& run_id) const {
  // The raw file is read back as errsep-separate-displacement reads it (format, completeness,
  // d_mm, uniform x checked there), so the folder's result is what that tool gives on the file.
  const io::OneAxisInput in = io::read_one_axis_csv(raw_csv);
  const fs::path residuals_in_place = fs::path(source).parent_path() / kDisplacementResidualsCsv;
  DisplacementPipelineResult out = compute({in}, {source}, residuals_in_place.string());
  out.profile.set_meta("source", source);
  out.profile.set_meta("run_id", run_id);
  out.residual_table.set_meta("source", source);
  out.residual_table.set_meta("run_id", run_id);
  // Where the scan ran, in machine coordinates (errsep-report names E_ZX etc. from it).
  const io::RawDisplacementScan raw =
      io::read_raw_displacement_csv(raw_csv, io::RawReadOptions{false});
  if (const auto axes = io::machine_axes_from_metadata(raw.metadata)) {
    out.profile.set_meta("axis", std::string(1, axes->input_axis));
    out.profile.set_meta("straightness_direction", std::string(1, axes->output_axis));
    for (const auto& [k, v] : io::machine_axes_metadata(*axes))
      out.profile.set_meta(k, v);
  }
  io::write_csv(dir / kDisplacementResidualsCsv, out.residual_table);
  io::write_csv(dir / kDisplacementResultCsv, out.profile);
  out.files = {kDisplacementResultCsv, kDisplacementResidualsCsv};
  if (opts_.refine) {
    // The loop (issue 16 item 4) on the recorded readings and their recorded times: its account
    // and the refined profile with its widened u, in refine/ of the same set.
    out.refine = refine(in, vector_of(raw.t_scan1_s), vector_of(raw.t_scan2_s), source);
    fs::create_directories(dir / "refine");
    io::CsvTable steps = io::displacement_refine_csv(*out.refine);
    steps.set_meta("source", source);
    steps.set_meta("run_id", run_id);
    io::write_csv(dir / kDisplacementRefineCsv, steps);
    io::CsvTable refined = io::one_axis_result_csv(in.x_mm, out.refine->refined);
    refined.set_meta("source", source);
    refined.set_meta("run_id", run_id);
    refined.set_meta("refine",
                     (fs::path("..") / kDisplacementRefineCsv).string() + ": " +
                         (out.refine->applied_any() ? "corrections applied" : "nothing applied") +
                         "; u widened by what was detected and not applied");
    io::write_csv(dir / kDisplacementRefinedCsv, refined);
    out.files.push_back(kDisplacementRefineCsv);
    out.files.push_back(kDisplacementRefinedCsv);
  }
  return out;
}

DisplacementPipelineResult DisplacementPipeline::write_result_set(
    const io::RawDisplacementScan& raw_in, const fs::path& out, const std::string& writer) const {
  io::StagedDirectory stage(out, {"scan", writer, false, {}});
  io::RawDisplacementScan raw = raw_in;
  raw.metadata.emplace(raw.metadata.begin(), "run_id", stage.run_id());
  const fs::path raw_csv = stage.dir() / kDisplacementRawCsv;
  io::write_raw_displacement_csv(raw_csv, raw);
  DisplacementPipelineResult res;
  try {
    res = separate(stage.dir(), raw_csv, (out / kDisplacementRawCsv).string(), stage.run_id());
  } catch (const std::exception& e) {
    // The measurements are kept: the set holds the raw file alone.
    for (const auto& entry : fs::directory_iterator(stage.dir()))
      if (entry.path().filename() != kDisplacementRawCsv) fs::remove_all(entry.path());
    res = {};
    res.error = e.what();
  }
  res.files.insert(res.files.begin(), kDisplacementRawCsv);
  stage.commit();
  return res;
}

}  // namespace errsep::service

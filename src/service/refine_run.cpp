#include "errsep/service/refine_run.hpp"

#include <cmath>
#include <cstdio>
#include <limits>
#include <system_error>

#include "errsep/core/four_sensor_model.hpp"
#include "errsep/io/atomic_file.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/four_sensor_result_csv.hpp"
#include "errsep/io/reference_csv.hpp"
#include "errsep/io/refine_report.hpp"
#include "errsep/io/staged_directory.hpp"
#include "errsep/service/sequence_result.hpp"
#include "errsep/version.hpp"

namespace errsep::service {

namespace fs = std::filesystem;

namespace {

Eigen::VectorXd vec(const std::vector<double>& v) {
  return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

void add_comparison(io::CsvTable& t, double code, const core::ReferenceComparison& b,
                    const core::ReferenceComparison& a) {
  for (Eigen::Index n = 0; n < b.x_mm.size(); ++n)
    t.rows.push_back({code, b.x_mm(n), b.reference(n), b.measured(n), a.measured(n),
                      b.difference(n), a.difference(n)});
}

}  // namespace

ReferenceReport compare_with_reference(const core::FourSensorResult& before,
                                       const core::FourSensorResult& after,
                                       const Eigen::VectorXd& x_mm, double dx_mm,
                                       const fs::path& reference_csv) {
  const io::ReferenceTrace tr = io::read_reference_csv(reference_csv);
  ReferenceReport rep;
  rep.file = reference_csv.string();
  const Eigen::VectorXd xr = vec(tr.x_mm);
  auto cmp = [&](const Eigen::VectorXd& x, const Eigen::VectorXd& v, const Eigen::VectorXd& ref,
                 core::ReferenceAlignment al) {
    core::ReferenceCompareOptions o;
    o.alignment = al;
    try {
      return core::compare_with_reference(x, v, xr, ref, o);
    } catch (const std::invalid_argument& e) {
      throw io::CsvError(reference_csv, 0, e.what());
    }
  };
  if (tr.S_um) {
    rep.S_before = cmp(x_mm, before.S_um, vec(*tr.S_um), core::ReferenceAlignment::line);
    rep.S_after = cmp(x_mm, after.S_um, vec(*tr.S_um), core::ReferenceAlignment::line);
  }
  if (tr.gamma_urad) {
    rep.gamma_before =
        cmp(x_mm, 1e6 * before.gamma_rad, vec(*tr.gamma_urad), core::ReferenceAlignment::offset);
    rep.gamma_after =
        cmp(x_mm, 1e6 * after.gamma_rad, vec(*tr.gamma_urad), core::ReferenceAlignment::offset);
  }
  if (tr.f_um) {
    const Eigen::VectorXd xf =
        x_mm(0) + dx_mm * Eigen::VectorXd::LinSpaced(before.f_um.size(), 0.0,
                                                     static_cast<double>(before.f_um.size() - 1))
                              .array();
    rep.f_before = cmp(xf, before.f_um, vec(*tr.f_um), core::ReferenceAlignment::line);
    rep.f_after = cmp(xf, after.f_um, vec(*tr.f_um), core::ReferenceAlignment::line);
  }
  return rep;
}

std::string format_reference_text(const ReferenceReport& r) {
  std::string out = "\ncomparison with the reference trace " + r.file +
                    "\n  (aligned as Zhao 2019 section 4: S and f rotated so that the 2-norm of "
                    "the difference is least, gamma's mean removed)\n";
  char buf[400];
  auto line = [&](const char* name, const char* unit,
                  const std::optional<core::ReferenceComparison>& b,
                  const std::optional<core::ReferenceComparison>& a) {
    if (!b || !a) return;
    std::snprintf(buf, sizeof buf,
                  "  %-6s RMS %.4g -> %.4g %s, max |d| %.4g -> %.4g %s over %d points (%d "
                  "outside the reference)\n",
                  name, b->rms, a->rms, unit, b->max_abs, a->max_abs, unit, b->points,
                  b->points_outside);
    out += buf;
  };
  line("S", "um", r.S_before, r.S_after);
  line("gamma", "urad", r.gamma_before, r.gamma_after);
  line("f", "um", r.f_before, r.f_after);
  return out;
}

RefineRunResult run_refine(const io::FourSensorInputs& in, const fs::path& out_dir,
                           const RefineRunOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("refine options: " + why);
  if (opts.sequence_refine &&
      (!in.sequence || opts.sequence_refine->after.residual_um.cols() != in.sequence->first.size()))
    throw std::invalid_argument(
        "refine options: sequence_refine is not a refine of this scan's recorded sequence");
  // Inputs first: nothing is written unless every file given reads.
  std::optional<core::RefineTruth> truth;
  if (opts.truth_csv) truth = io::read_truth_csv(*opts.truth_csv, in.cfg, in.x_mm(0));
  if (opts.reference_csv) (void)io::read_reference_csv(*opts.reference_csv);

  RefineRunResult out;
  core::RefineOptions ro = opts.refine;
  if (in.sequence) {
    // The direction of each configuration's first traverse (m1..m4 are those traverses), for
    // the residual trace.
    const core::ScanSequence& seq = in.sequence->first;
    ro.recorded_direction = Eigen::MatrixXd::Ones(in.m_um.rows(), 4);
    for (int c = 0; c < 4; ++c)
      for (const auto& tr : seq.traverses)
        if (tr.configuration == c) {
          if (tr.direction == core::TraverseDirection::backward) ro.recorded_direction.col(c) *= -1;
          break;
        }
  }
  if (in.sequence) {
    // The redundant traverses (issue 16 items 2, 3): a knocked sensor the repeated traverses
    // name, drift, thermal drift and a non-repeating traverse, applied only where the plan
    // identifies them, said where it does not.
    if (opts.sequence_refine) {
      out.sequence = *opts.sequence_refine;
      out.sequence_taken = true;
    } else {
      core::SequenceRefineOptions so;
      so.alpha = opts.refine.alpha;
      out.sequence =
          core::refine_four_sensor_sequence(in.cfg, in.sequence->first, in.sequence->second, so);
    }
    // m1..m4 are each configuration's first traverse: a knock the sequence named in one of them
    // is a step there, attributed by the repeats (gross_errors.hpp) for the single refine too.
    const core::SequenceKnock& kn = out.sequence->knock;
    if (kn.fitted && kn.applied) {
      const core::ScanSequence& seq = in.sequence->first;
      int first = -1;
      for (int k = 0; k < seq.size() && first < 0; ++k)
        if (seq.traverses[static_cast<std::size_t>(k)].configuration == kn.scan.configuration)
          first = k;
      if (first == kn.traverse)
        ro.gross.attributed_steps.push_back({kn.scan.configuration, kn.scan.position, kn.size_um,
                                             kn.u_size_um, "the configuration's two traverses"});
    }
  }
  out.result = core::refine_four_sensor(in.cfg, in.m_um, in.t_s, ro, truth ? &*truth : nullptr);
  const core::RefineResult& r = out.result;
  if (opts.reference_csv)
    out.reference =
        compare_with_reference(r.before, r.after, in.x_mm, in.cfg.dx_mm, *opts.reference_csv);
  out.text = io::format_refine_text(r);
  if (out.reference) out.text += format_reference_text(*out.reference);
  if (out.sequence) {
    out.text += "\nScan sequence (plan: " + out.sequence->plan + ", " +
                std::to_string(in.sequence->first.size()) + " traverses):\n";
    for (const auto& line : out.sequence->report)
      out.text += "  " + line + "\n";
    if (out.sequence->report.empty())
      out.text +=
          "  nothing detected: no knocked sensor, drift, thermal drift or non-repeating "
          "traverse\n";
    if (sequence_is_the_result(in.sequence->first))
      out.text +=
          "  motion.csv, reference.csv, residuals.csv and summary.txt hold this refined fit of "
          "every traverse (the scan's result); the steps above are the single-scan refine of "
          "each configuration's first traverse (m1..m4), for comparison\n";
  }
  // One result set: the files appear in DIR only when all are written, replacing an earlier
  // refine result whole (io/staged_directory.hpp).
  io::StagedDirectory stage(out_dir,
                            {"refine", std::string("errsep-refine ") + kVersion, false, {}});
  out.swept = stage.swept();
  io::CsvTable steps = io::refine_csv(r);
  steps.set_meta("source", opts.source);
  // Whose figures the step table's findings concern (errsep-report words its warnings by it):
  // on a scan sequence whose refined fit is the result, the table is the single-scan refine of
  // m1..m4, kept for comparison.
  const bool comparison = out.sequence && sequence_is_the_result(in.sequence->first);
  steps.set_meta(io::kRefineRoleKey,
                 io::to_string(comparison ? io::RefineRole::comparison : io::RefineRole::result));
  steps.set_meta("run_id", stage.run_id());
  io::write_csv(stage.dir() / "refine_steps.csv", steps);
  io::write_file_atomic(stage.dir() / "refine_report.txt", out.text);
  if (out.sequence) {
    std::vector<double> x(in.x_mm.data(), in.x_mm.data() + in.x_mm.size());
    io::CsvTable sq = io::sequence_refine_csv(*out.sequence, x);
    sq.set_meta("source", opts.source);
    sq.set_meta("run_id", stage.run_id());
    io::write_csv(stage.dir() / "sequence_refine.csv", sq);
  }
  io::ResultWriteInfo info{opts.source, "X", "Y", {}};
  if (comparison) {
    // The sequence's refined fit is the result of such a scan (service/four_sensor_pipeline.hpp):
    // the refined files say the same, not the weaker single-scan refine of m1..m4.
    info.extra_metadata = {{"run_id", stage.run_id()}};
    describe_sequence_result(in.cfg, in.sequence->first, *out.sequence, in.x_mm, info);
    info.summary_notes.push_back(
        "refine_steps.csv and refine_report.txt: the single-scan refine of each configuration's "
        "first traverse (m1..m4, model " +
        r.model_name + "), for comparison");
    io::write_four_sensor_result(
        stage.dir(), sequence_as_result(r.before, in.sequence->first, *out.sequence), info);
  } else {
    info.extra_metadata = {{"run_id", stage.run_id()},
                           {"model", r.model_name},
                           {"refine_residual_white", r.residual_white() ? "true" : "false"},
                           {"refine_stop_reason", r.stop_reason}};
    // The refined u_S holds a term the data do not bound at the readings' bound: the result file
    // says so beside its u_S_um column (refine_steps.csv names the effect).
    if (!r.unbounded.empty()) {
      info.extra_metadata.emplace_back("u_S_bounded_by_data", "false");
      for (const auto& line : r.unbounded)
        info.summary_notes.push_back(line);
    }
    io::write_four_sensor_result(stage.dir(), r.after, info);
  }
  {
    // The residual of every reading under the final model (least squares, Eq. 1 plus the added
    // effects), with its time: what the whiteness tests looked at.
    const core::ResidualAnalysis& ra = r.residual;
    const core::WhitenessTest& w = ra.whiteness;
    io::CsvTable t;
    t.set_meta("format", "errsep refine residual");
    t.set_meta("source", opts.source);
    t.set_meta("run_id", stage.run_id());
    t.set_meta("model", r.model_name);
    t.set_meta("sigma_hat_um", std::to_string(ra.sigma_um));
    t.set_meta("dof", std::to_string(ra.dof));
    t.set_meta("whiteness_p", std::to_string(w.p_value));
    t.set_meta("whiteness_p_ljung_box", std::to_string(w.p_ljung_box));
    t.set_meta("whiteness_p_periodogram", std::to_string(w.p_periodogram));
    t.set_meta("whiteness_p_cumulative_periodogram", std::to_string(w.p_cumulative_periodogram));
    t.set_meta("whiteness_p_runs", std::to_string(w.p_runs));
    t.set_meta("whiteness_p_local", std::to_string(w.p_local));
    t.set_meta("residual_white", r.residual_white() ? "true" : "false");
    t.columns = {"x_mm", "config", "t_s", "residual_um"};
    for (Eigen::Index n = 0; n < ra.residual_um.rows(); ++n)
      for (Eigen::Index i = 0; i < 4; ++i)
        t.rows.push_back(
            {in.x_mm(n), static_cast<double>(i + 1), r.t_s(n, i), ra.residual_um(n, i)});
    io::write_csv(stage.dir() / "refine_residual.csv", t);
  }
  if (out.reference) {
    const ReferenceReport& rep = *out.reference;
    io::CsvTable t;
    t.set_meta("format", "errsep reference comparison");
    t.set_meta("run_id", stage.run_id());
    t.set_meta("reference", rep.file);
    t.set_meta("model", r.model_name);
    t.set_meta("profile", "0 = S (um), 1 = gamma (urad), 2 = f (um)");
    t.set_meta("alignment",
               "S, f: best-fit line of the difference removed (Zhao 2019 section 4); gamma: mean "
               "removed");
    t.columns = {"profile", "x_mm", "reference", "before", "after", "diff_before", "diff_after"};
    if (rep.S_before) add_comparison(t, 0, *rep.S_before, *rep.S_after);
    if (rep.gamma_before) add_comparison(t, 1, *rep.gamma_before, *rep.gamma_after);
    if (rep.f_before) add_comparison(t, 2, *rep.f_before, *rep.f_after);
    io::write_csv(stage.dir() / "reference_comparison.csv", t);
  }
  out.files = stage.commit();
  return out;
}

RefineRunResult run_refine(const fs::path& raw_csv, const fs::path& out_dir,
                           const RefineRunOptions& opts, const io::GeometryOverrides& geometry) {
  const io::RawFourSensorScan raw = io::read_raw_four_sensor_csv(raw_csv);
  const io::FourSensorInputs in = io::four_sensor_inputs(raw, raw_csv, geometry);
  RefineRunOptions o = opts;
  if (o.source.empty()) o.source = raw_csv.string();
  return run_refine(in, out_dir, o);
}

}  // namespace errsep::service

#include "errsep/io/refine_run.hpp"

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
#include "errsep/version.hpp"

namespace errsep::io {

namespace fs = std::filesystem;

FourSensorInputs four_sensor_inputs(const RawFourSensorScan& raw, const fs::path& file,
                                    const GeometryOverrides& geometry) {
  FourSensorInputs in;
  core::FourSensorConfig& cfg = in.cfg;
  if (raw.geometry) cfg = *raw.geometry;
  if (geometry.s2 > 0) cfg.s2 = geometry.s2;
  if (geometry.s3 > 0) cfg.s3 = geometry.s3;
  if (geometry.s4 > 0) cfg.s4 = geometry.s4;
  const auto P = static_cast<int>(raw.positions());
  if (P < 2) throw CsvError(file, 0, "need at least 2 slide positions, got " + std::to_string(P));
  if (geometry.dx_mm > 0)
    cfg.dx_mm = geometry.dx_mm;
  else if (!raw.geometry)
    cfg.dx_mm = raw.x_mm[1] - raw.x_mm[0];
  // The rows must lie on the Δx grid: x_n = x_0 + n·Δx (Eq. 5).
  for (int n = 0; n < P; ++n) {
    const double x = raw.x_mm[static_cast<std::size_t>(n)];
    const double expect = raw.x_mm[0] + n * cfg.dx_mm;
    if (!(std::abs(x - expect) <= 1e-6 * std::max(1.0, cfg.dx_mm)))
      throw CsvError(file, 0,
                     "x_mm of data row " + std::to_string(n + 1) + " is " + std::to_string(x) +
                         ", expected " + std::to_string(expect) +
                         " (rows must be on the dx = " + std::to_string(cfg.dx_mm) + " mm grid)");
  }
  cfg.N = P + cfg.s2 + cfg.s3 + cfg.s4;
  std::string why;
  if (!cfg.is_valid(&why))
    throw CsvError(file, 0, std::to_string(P) + " rows do not fit the spacing: " + why);
  in.x_mm.resize(P);
  in.m_um.resize(P, 4);
  for (int n = 0; n < P; ++n) {
    in.x_mm(n) = raw.x_mm[static_cast<std::size_t>(n)];
    for (int j = 0; j < 4; ++j) {
      const double v = raw.m_um[static_cast<std::size_t>(j)][static_cast<std::size_t>(n)];
      if (!std::isfinite(v))
        throw CsvError(file, 0,
                       "m" + std::to_string(j + 1) + "_um of data row " + std::to_string(n + 1) +
                           " is not a finite number");
      in.m_um(n, j) = v;
    }
  }
  if (raw.t_s) {
    in.t_s.resize(P, 4);
    for (int n = 0; n < P; ++n)
      for (int j = 0; j < 4; ++j) {
        const double v = (*raw.t_s)[static_cast<std::size_t>(j)][static_cast<std::size_t>(n)];
        if (!std::isfinite(v))
          throw CsvError(file, 0,
                         "t" + std::to_string(j + 1) + "_s of data row " + std::to_string(n + 1) +
                             " is not a finite number");
        in.t_s(n, j) = v;
      }
  }
  if (raw.sequence) {
    RawFourSensorScan r = raw;
    r.geometry = cfg;
    in.sequence = scan_sequence_of(r);
    if (!in.sequence->second.allFinite())
      throw CsvError(file, 0, "a traverse column (kK_um) holds a value that is not finite");
  }
  return in;
}

namespace {

Eigen::VectorXd vec(const std::vector<double>& v) {
  return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

void add_comparison(CsvTable& t, double code, const core::ReferenceComparison& b,
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
  const ReferenceTrace tr = read_reference_csv(reference_csv);
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
      throw CsvError(reference_csv, 0, e.what());
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

RefineRunResult run_refine(const FourSensorInputs& in, const fs::path& out_dir,
                           const RefineRunOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("refine options: " + why);
  // Inputs first: nothing is written unless every file given reads.
  std::optional<core::RefineTruth> truth;
  if (opts.truth_csv) truth = read_truth_csv(*opts.truth_csv, in.cfg, in.x_mm(0));
  if (opts.reference_csv) (void)read_reference_csv(*opts.reference_csv);

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
    core::SequenceRefineOptions so;
    so.alpha = opts.refine.alpha;
    out.sequence =
        core::refine_four_sensor_sequence(in.cfg, in.sequence->first, in.sequence->second, so);
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
  out.text = format_refine_text(r);
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
  }
  // One result set: the files appear in DIR only when all are written, replacing an earlier
  // refine result whole (io/staged_directory.hpp).
  StagedDirectory stage(out_dir, {"refine", std::string("errsep-refine ") + kVersion, false, {}});
  out.swept = stage.swept();
  CsvTable steps = refine_csv(r);
  steps.set_meta("source", opts.source);
  steps.set_meta("run_id", stage.run_id());
  write_csv(stage.dir() / "refine_steps.csv", steps);
  write_file_atomic(stage.dir() / "refine_report.txt", out.text);
  if (out.sequence) {
    std::vector<double> x(in.x_mm.data(), in.x_mm.data() + in.x_mm.size());
    CsvTable sq = sequence_refine_csv(*out.sequence, x);
    sq.set_meta("source", opts.source);
    sq.set_meta("run_id", stage.run_id());
    write_csv(stage.dir() / "sequence_refine.csv", sq);
  }
  ResultWriteInfo info{opts.source, "X", "Y", {}};
  info.extra_metadata = {{"run_id", stage.run_id()},
                         {"model", r.model_name},
                         {"refine_residual_white", r.residual_white() ? "true" : "false"},
                         {"refine_stop_reason", r.stop_reason}};
  write_four_sensor_result(stage.dir(), r.after, info);
  {
    // The residual of every reading under the final model (least squares, Eq. 1 plus the added
    // effects), with its time: what the whiteness tests looked at.
    const core::ResidualAnalysis& ra = r.residual;
    const core::WhitenessTest& w = ra.whiteness;
    CsvTable t;
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
    write_csv(stage.dir() / "refine_residual.csv", t);
  }
  if (out.reference) {
    const ReferenceReport& rep = *out.reference;
    CsvTable t;
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
    write_csv(stage.dir() / "reference_comparison.csv", t);
  }
  out.files = stage.commit();
  return out;
}

RefineRunResult run_refine(const fs::path& raw_csv, const fs::path& out_dir,
                           const RefineRunOptions& opts, const GeometryOverrides& geometry) {
  const RawFourSensorScan raw = read_raw_four_sensor_csv(raw_csv);
  const FourSensorInputs in = four_sensor_inputs(raw, raw_csv, geometry);
  RefineRunOptions o = opts;
  if (o.source.empty()) o.source = raw_csv.string();
  return run_refine(in, out_dir, o);
}

}  // namespace errsep::io

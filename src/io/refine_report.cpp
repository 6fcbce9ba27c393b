#include "errsep/io/refine_report.hpp"

#include <cmath>
#include <cstdio>
#include <limits>
#include <map>

namespace errsep::io {

std::string lambda_summary(const core::FourSensorResult& sep) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.4g (", sep.lambda);
  std::string out = buf + std::string(core::to_string(sep.rule));
  if (sep.lambda_fallback != core::LambdaFallback::none)
    out += std::string(", ") + core::to_string(sep.lambda_fallback);
  return out + ")";
}

const char* to_string(RefineRole r) {
  switch (r) {
    case RefineRole::result:
      return "result";
    case RefineRole::comparison:
      return "comparison";
  }
  return "?";
}

RefineRole refine_role_of(const CsvTable& steps, const std::filesystem::path& file) {
  const auto v = steps.meta(kRefineRoleKey);
  if (!v) return RefineRole::result;
  for (const RefineRole r : {RefineRole::result, RefineRole::comparison})
    if (*v == to_string(r)) return r;
  throw CsvError(file, steps.meta_line(kRefineRoleKey),
                 std::string("metadata '") + kRefineRoleKey + ": " + *v +
                     "': neither 'result' nor 'comparison'");
}

const std::vector<std::string>& refine_csv_columns() {
  static const std::vector<std::string> columns = {"step",
                                                   "parameter_index",
                                                   "value",
                                                   "u_value",
                                                   "F",
                                                   "p_value",
                                                   "rms_before_um",
                                                   "rms_after_um",
                                                   "whiteness_p",
                                                   "S_err_before_um",
                                                   "S_err_after_um",
                                                   "gamma_err_before_urad",
                                                   "gamma_err_after_urad",
                                                   "f_err_before_um",
                                                   "f_err_after_um",
                                                   "applied"};
  return columns;
}

CsvTable refine_csv(const core::RefineResult& r) {
  CsvTable t;
  t.set_meta("format", "errsep refine steps");
  t.set_meta("model", r.model_name);
  t.set_meta("stop_reason", r.stop_reason);
  t.set_meta("residual_white", r.residual_white() ? "true" : "false");
  t.set_meta("model_complete", r.model_complete() ? "true" : "false");
  // Significant candidates not added because their fitted parameters are physically implausible.
  for (std::size_t i = 0; i < r.rejected.size(); ++i) {
    const std::string key = "rejected" + std::to_string(i);
    t.set_meta(key + "_effect", r.rejected[i].effect);
    t.set_meta(key + "_round", std::to_string(r.rejected[i].round));
    t.set_meta(key + "_status", r.rejected[i].reason);
  }
  for (std::size_t i = 0; i < r.implausible_kept.size(); ++i)
    t.set_meta("implausible_kept" + std::to_string(i), r.implausible_kept[i]);
  // A u_S term the data do not bound (RefineResult::unbounded): the refined u_S holds it at the
  // readings' bound, a finite number that is not a measured bound; the file says so, so the
  // report can warn beside the figures.
  for (std::size_t i = 0; i < r.unbounded.size(); ++i)
    t.set_meta("u_S_unbounded" + std::to_string(i), r.unbounded[i]);
  // The errors before and after are those of two separations with the same solver options; the
  // λ rule may regularise one and not the other (an undeclared effect can give the L-curve a
  // corner that the corrected readings no longer have), so both λ go with them.
  t.set_meta("lambda_before", lambda_summary(r.before));
  t.set_meta("lambda_after", lambda_summary(r.after));
  // The declared Type-B bounds (RefineOptions::declared): part of u_S, never fitted; the report
  // prints them beside the steps (refine_steps_table), so the file carries them.
  for (std::size_t i = 0; i < r.declared_notes.size(); ++i)
    t.set_meta("declared" + std::to_string(i), r.declared_notes[i]);
  t.columns = refine_csv_columns();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (const auto& s : r.steps) {
    t.set_meta("step" + std::to_string(s.index) + "_effect", s.effect);
    if (s.index > 0) t.set_meta("step" + std::to_string(s.index) + "_verdict", s.verdict);
    const Eigen::Index k = std::max<Eigen::Index>(1, s.parameters.size());
    for (Eigen::Index j = 0; j < k; ++j) {
      const bool has = j < s.parameters.size();
      if (has)
        t.set_meta("step" + std::to_string(s.index) + "_parameter" + std::to_string(j),
                   s.parameter_names[static_cast<std::size_t>(j)]);
      const auto& eb = s.error_before;
      const auto& ea = s.error_after;
      t.rows.push_back({static_cast<double>(s.index), has ? static_cast<double>(j) : nan,
                        has ? s.parameters(j) : nan, has ? s.u_parameters(j) : nan, s.F, s.p_value,
                        s.rms_before_um, s.rms_after_um, s.whiteness_after.p_value,
                        eb ? eb->S_um : nan, ea ? ea->S_um : nan, eb ? eb->gamma_urad : nan,
                        ea ? ea->gamma_urad : nan, eb ? eb->f_um : nan, ea ? ea->f_um : nan,
                        s.index > 0 ? (s.applied ? 1.0 : 0.0) : nan});
    }
  }
  return t;
}

std::string format_refine_text(const core::RefineResult& r) {
  std::string out = "errsep refine: " + r.brief_report() + "\n\n";
  char buf[512];
  for (const auto& s : r.steps) {
    std::snprintf(buf, sizeof buf,
                  "step %d: %s  (F = %.4g, p = %.3g)\n  residual RMS %.4g -> %.4g um, sigma_hat "
                  "%.3g um (dof %d), whiteness p = %.3g%s\n",
                  s.index, s.effect.c_str(), s.F, s.p_value, s.rms_before_um, s.rms_after_um,
                  s.sigma_after_um, s.dof_after, s.whiteness_after.p_value,
                  s.whiteness_after.white ? "" : "  NOT WHITE");
    out += buf;
    if (!s.description.empty()) out += "  " + s.description + "\n";
    for (Eigen::Index j = 0; j < s.parameters.size(); ++j) {
      std::snprintf(buf, sizeof buf, "    %-14s = %.6g  (u = %.3g, k = 1)\n",
                    s.parameter_names[static_cast<std::size_t>(j)].c_str(), s.parameters(j),
                    s.u_parameters(j));
      out += buf;
    }
    if (s.index > 0) {
      std::snprintf(buf, sizeof buf, "    determined parameter combinations: %d of %zd\n",
                    s.identifiable, static_cast<std::ptrdiff_t>(s.parameters.size()));
      out += buf;
      out += "  " + std::string(s.applied ? "APPLIED: " : "NOT APPLIED: ") + s.verdict + "\n";
    }
    if (s.error_before && s.error_after) {
      std::snprintf(buf, sizeof buf,
                    "  error vs truth: S %.4g -> %.4g um, gamma %.4g -> %.4g urad, f %.4g -> "
                    "%.4g um\n",
                    s.error_before->S_um, s.error_after->S_um, s.error_before->gamma_urad,
                    s.error_after->gamma_urad, s.error_before->f_um, s.error_after->f_um);
      out += buf;
    }
  }
  // The declared bounds (Type B) enter u_S beside the steps' fitted parameters: said where the
  // steps are, so that a u_S larger than the steps explain is accounted for.
  if (!r.declared_notes.empty()) {
    out += "\ndeclared bounds (Type B, RefineOptions::declared; not fitted, carried in u):\n";
    for (const auto& n : r.declared_notes)
      out += "  " + n + "\n";
  }
  if (!r.effects.empty()) {
    out += "\nthe refined result (final parameters):\n";
    for (std::size_t e = 0; e < r.verdicts.size(); ++e)
      out +=
          std::string("  ") + (r.applied[e] ? "APPLIED: " : "NOT APPLIED: ") + r.verdicts[e] + "\n";
    out +=
        "  (u_S, u_gamma, u_f of the refined result carry the applied parameters' covariance, the "
        "fitted size of the effects not applied and the part this plan cannot determine; the "
        "constant, line and bow of S and the constant and line of gamma are those of the raw "
        "readings' separation: a step does not move what one scan cannot see)\n";
  }
  // Why an error "before" can be smaller than the noise floor: see refine_csv.
  out += "\nseparations: raw readings lambda = " + lambda_summary(r.before) +
         ", corrected readings lambda = " + lambda_summary(r.after) + "\n";
  if (r.before.regularised() != r.after.regularised())
    out += std::string("  only the ") + (r.before.regularised() ? "raw" : "corrected") +
           " readings' separation is regularised: its errors carry shrinkage (less noise, more "
           "bias), the other's do not\n";
  for (const auto& rc : r.rejected) {
    std::snprintf(buf, sizeof buf, "\nround %d: %s  (F = %.4g, p = %.3g) NOT ADDED\n", rc.round + 1,
                  rc.effect.c_str(), rc.F, rc.p_value);
    out += buf;
    out += "  " + rc.reason + "\n";
    for (Eigen::Index j = 0; j < rc.parameters.size(); ++j) {
      std::snprintf(buf, sizeof buf, "    %-14s = %.6g  (u = %.3g, k = 1)\n",
                    rc.parameter_names[static_cast<std::size_t>(j)].c_str(), rc.parameters(j),
                    rc.u_parameters(j));
      out += buf;
    }
  }
  out += "\ncandidates when the loop stopped (" + r.stop_reason + "):\n";
  for (const auto& c : r.final_round) {
    std::snprintf(buf, sizeof buf, "  %-9s F = %-9.4g p = %-9.3g identifiable %d of %d\n",
                  c.effect.c_str(), c.F, c.p_value, c.identifiable, c.parameters);
    out += buf;
  }
  const core::WhitenessTest& w = r.residual.whiteness;
  {
    // Where the residual sits: per configuration, and the positions with the largest RMS.
    const core::ResidualAnalysis& ra = r.residual;
    std::snprintf(buf, sizeof buf,
                  "\nresidual of the final model: sigma_hat %.3g um (dof %d); RMS per "
                  "configuration %.3g, %.3g, %.3g, %.3g um\n",
                  ra.sigma_um, ra.dof, ra.rms_per_config_um(0), ra.rms_per_config_um(1),
                  ra.rms_per_config_um(2), ra.rms_per_config_um(3));
    out += buf;
  }
  std::snprintf(buf, sizeof buf,
                "\nwhiteness of the final residual (Monte-Carlo p-values, %d draws):\n"
                "  Ljung-Box %.3g, periodogram peak %.3g (period %.4g mm), cumulative "
                "periodogram %.3g,\n  runs in time order %.3g, local excess %.3g (largest %.5g mm "
                "from the first position, over %.4g mm); combined p = %.3g (alpha %.3g)\n",
                w.mc_samples, w.p_ljung_box, w.p_periodogram, r.residual.dominant_period_mm,
                w.p_cumulative_periodogram, w.p_runs, w.p_local, w.local_x_mm, w.local_width_mm,
                w.p_value, r.alpha_residual);
  out += buf;
  for (const auto& k : r.implausible_kept)
    out += "\nWARNING: " + k + ".\n";
  if (r.residual_white() && r.rejected.empty() && r.implausible_kept.empty()) {
    out += "\nThe final residual passes the whiteness test.\n";
  } else if (r.residual_white()) {
    out +=
        "\nThe final residual passes the whiteness test, but the model is still incomplete: "
        "significant effects fitted only with implausible parameters (see above), so the data "
        "hold something the library does not describe.\n";
  } else {
    out += "\nThe final residual is NOT white (" + w.rejected_by +
           "): the model is incomplete, it still lacks something the library does not describe";
    if (w.p_local < r.alpha_residual) {
      std::snprintf(buf, sizeof buf,
                    ", with structure concentrated %.5g mm from the first position", w.local_x_mm);
      out += buf;
    }
    out += ".";
    if (!r.rejected.empty())
      out += "  Effects that would explain it only with implausible parameters were rejected.";
    if (!r.effects.empty())
      out +=
          "  The effects added may partly stand in for it; treat their parameters with "
          "caution.";
    out += "\n";
  }
  return out;
}

namespace {

std::string g(double v, int digits) {
  if (!std::isfinite(v)) return "\xE2\x80\x94";  // not applicable / not known
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  return buf;
}

std::string before_after(double before, double after) {
  if (!std::isfinite(before) && !std::isfinite(after)) return "\xE2\x80\x94";
  return g(before, 4) + " \xE2\x86\x92 " + g(after, 4);
}

}  // namespace

HtmlTable refine_steps_table(const CsvTable& t, const std::filesystem::path& file) {
  const auto col = [&](const char* name) {
    const auto c = t.find_column(name);
    if (!c) throw CsvError(file, 1, std::string("refine steps: no column '") + name + "'");
    return *c;
  };
  const std::size_t c_step = col("step"), c_par = col("parameter_index"), c_val = col("value"),
                    c_u = col("u_value"), c_F = col("F"), c_p = col("p_value"),
                    c_rb = col("rms_before_um"), c_ra = col("rms_after_um"),
                    c_sb = col("S_err_before_um"), c_sa = col("S_err_after_um"),
                    c_gb = col("gamma_err_before_urad"), c_ga = col("gamma_err_after_urad"),
                    c_fb = col("f_err_before_um"), c_fa = col("f_err_after_um");
  // The errors against the truth exist only when the run was given one (errsep-refine --truth).
  bool truth = false;
  for (const auto& r : t.rows)
    truth = truth || std::isfinite(r[c_sb]) || std::isfinite(r[c_sa]);
  HtmlTable h;
  h.id = "refine";
  h.caption = "Refine steps (" + file.filename().string() + "): model " +
              t.meta("model").value_or("?") + "; stopped: " + t.meta("stop_reason").value_or("?") +
              "; residual white: " + t.meta("residual_white").value_or("?") + "; lambda before " +
              t.meta("lambda_before").value_or("?") + ", after " +
              t.meta("lambda_after").value_or("?") + ". Parameters: value \xC2\xB1 u (k = 1).";
  h.header = {"step", "effect", "parameters",
              "F",    "p",      "residual RMS before \xE2\x86\x92 after / \xC2\xB5m"};
  if (truth)
    for (const char* s : {"S error vs truth / \xC2\xB5m", "\xCE\xB3 error vs truth / \xC2\xB5rad",
                          "f error vs truth / \xC2\xB5m"})
      h.header.push_back(std::string(s) + " (before \xE2\x86\x92 after)");
  h.header.push_back("verdict");
  // One CSV row per parameter of a step: gather each step's rows.
  std::map<int, std::vector<const std::vector<double>*>> by_step;
  for (const auto& r : t.rows) {
    if (!std::isfinite(r[c_step]))
      throw CsvError(file, 0, "refine steps: a row without a step number");
    by_step[static_cast<int>(r[c_step])].push_back(&r);
  }
  for (const auto& [step, rows] : by_step) {
    const std::string k = "step" + std::to_string(step);
    const auto effect = t.meta(k + "_effect");
    if (!effect) throw CsvError(file, 0, "refine steps: no '# " + k + "_effect:' metadata");
    std::string params;
    for (const auto* r : rows) {
      if (!std::isfinite((*r)[c_par])) continue;
      const std::string name =
          t.meta(k + "_parameter" + std::to_string(static_cast<int>((*r)[c_par]))).value_or("?");
      params += (params.empty() ? "" : ", ") + name + " = " + g((*r)[c_val], 4) + " \xC2\xB1 " +
                g((*r)[c_u], 2);
    }
    const auto& r = *rows.front();
    std::vector<std::string> cells = {
        std::to_string(step), *effect,      params.empty() ? "\xE2\x80\x94" : params,
        g(r[c_F], 4),         g(r[c_p], 3), before_after(r[c_rb], r[c_ra])};
    if (truth) {
      cells.push_back(before_after(r[c_sb], r[c_sa]));
      cells.push_back(before_after(r[c_gb], r[c_ga]));
      cells.push_back(before_after(r[c_fb], r[c_fa]));
    }
    cells.push_back(step == 0 ? "base model" : t.meta(k + "_verdict").value_or("?"));
    h.rows.push_back(std::move(cells));
  }
  // The declared Type-B bounds (refine_csv's "declared<i>" lines), one row each after the steps:
  // they are in u_S as the steps' parameters are, but stated by the user, not fitted.
  for (std::size_t i = 0;; ++i) {
    const auto note = t.meta("declared" + std::to_string(i));
    if (!note) break;
    std::vector<std::string> cells(h.header.size(), "\xE2\x80\x94");
    cells.front() = "Type B";
    cells[1] = *note;
    cells.back() = "declared bound: carried in u, not fitted";
    h.rows.push_back(std::move(cells));
  }
  return h;
}

CsvTable sequence_refine_csv(const core::SequenceRefineResult& r, const std::vector<double>& x_mm) {
  const auto P = static_cast<std::size_t>(r.before.S_um.size());
  if (x_mm.size() != P)
    throw std::invalid_argument("sequence_refine_csv: " + std::to_string(x_mm.size()) +
                                " positions for " + std::to_string(P) + " values of S");
  CsvTable t;
  t.set_meta("format", "errsep sequence refine");
  t.set_meta("units", "x in mm, S and u in um (k = 1, about the best-fit constant, line and bow)");
  t.set_meta("plan", r.plan);
  std::string added;
  for (const auto& a : r.added)
    added += (added.empty() ? "" : ", ") + std::string(core::to_string(a.kind));
  t.set_meta("added", added.empty() ? "none" : added);
  // A knocked sensor the repeated traverses named (core::SequenceKnock), fitted before the effects.
  const core::SequenceKnock& kn = r.knock;
  if (kn.fitted) {
    t.set_meta("knock_configuration", std::to_string(kn.scan.configuration + 1));
    t.set_meta("knock_traverse",
               std::to_string(kn.traverse + 1) +
                   (kn.traverse_ambiguous ? " (or its pair: not told apart)" : ""));
    t.set_meta("knock_x_mm", g(kn.x_mm, 6));
    t.set_meta("knock_size_um", g(kn.size_um, 4) + " +- " + g(kn.u_size_um, 2));
    t.set_meta("knock_removed", kn.applied ? "true" : "false");
  } else {
    t.set_meta("knock", kn.scan.not_tested.empty()
                            ? (kn.scan.found ? "found, not attributed" : "none found")
                            : kn.scan.not_tested);
  }
  // The sensor's hysteresis (core::SequenceHysteresis): its figures when detected, else whether
  // the plan could show it.
  const core::SequenceHysteresis& hy = r.hysteresis;
  if (hy.detected) {
    t.set_meta("hysteresis_um", g(hy.h_um, 4) + " +- " + g(hy.u_h_um, 2));
    t.set_meta("hysteresis_applied", hy.applied ? "true" : "false");
    if (!hy.decision.empty()) t.set_meta("hysteresis_decision", hy.decision);
  } else {
    t.set_meta("hysteresis", hy.identifiable ? "none found" : hy.finding);
  }
  t.set_meta("findings", std::to_string(r.report.size()));
  for (std::size_t k = 0; k < r.report.size(); ++k)
    t.set_meta("finding_" + std::to_string(k + 1), r.report[k]);
  // As refine_csv's: a term of u_S held at the readings' bound, one key each (errsep-report warns).
  for (std::size_t i = 0; i < r.unbounded.size(); ++i)
    t.set_meta("u_S_unbounded" + std::to_string(i), r.unbounded[i]);
  auto col = [P](const Eigen::VectorXd& v) {
    std::vector<double> c(P, 0.0);
    for (std::size_t n = 0; n < P && n < static_cast<std::size_t>(v.size()); ++n)
      c[n] = v(static_cast<Eigen::Index>(n));
    return c;
  };
  t.add_column("x_mm", x_mm);
  t.add_column("S_before_um", col(r.before.S_um));
  t.add_column("u_S_before_um", col(r.before.u_S_um));
  t.add_column("S_after_um", col(r.after.S_um));
  t.add_column("u_S_after_um", col(r.after.u_S_um));
  t.add_column("u_S_widening_um", col(r.u_S_widening_um));
  t.add_column("u_S_knock_um", col(r.knock.u_S_added_um));
  // The rest of u_S_after's parts (each in quadrature, zero when it adds nothing): a step declined
  // (its bias), the drift's form when the data do not tell linear from thermal, a hysteresis
  // detected and not applied.  A user reads from them why u_S grew.
  t.add_column("u_S_declined_um", col(r.u_S_declined_um));
  t.add_column("u_S_drift_form_um", col(r.u_S_drift_form_um));
  t.add_column("u_S_hysteresis_um", col(hy.u_S_added_um));
  return t;
}

HtmlTable sequence_findings_table(const CsvTable& t, const std::filesystem::path& file) {
  if (t.meta("format") != std::optional<std::string>("errsep sequence refine"))
    throw CsvError(file, 0, "not a sequence refine file ('# format: errsep sequence refine')");
  HtmlTable out;
  out.id = "sequence_refine";
  out.caption = "Scan sequence (plan: " + t.meta("plan").value_or("unknown") +
                "): what the redundant traverses show; added to the model: " +
                t.meta("added").value_or("none");
  out.header = {"finding"};
  const auto n = t.meta("findings");
  if (!n) throw CsvError(file, 0, "metadata 'findings' missing");
  const int count = std::atoi(n->c_str());
  for (int k = 1; k <= count; ++k) {
    const auto f = t.meta("finding_" + std::to_string(k));
    if (!f) throw CsvError(file, 0, "metadata 'finding_" + std::to_string(k) + "' missing");
    out.rows.push_back({*f});
  }
  if (out.rows.empty())
    out.rows.push_back({"nothing detected: no drift, thermal drift or non-repeating traverse"});
  return out;
}

}  // namespace errsep::io

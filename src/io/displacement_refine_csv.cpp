#include "errsep/io/displacement_refine_csv.hpp"

#include "displacement_refine_account.hpp"

#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

namespace errsep::io {
namespace {

std::string fmt(double v, const char* f = "%.3g") {
  if (!std::isfinite(v)) return "-";
  char buf[48];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

}  // namespace

CsvTable displacement_refine_csv(const core::OneAxisRefineResult& r) {
  CsvTable t = detail::displacement_refine_account(
      "one-axis displacement method (Haramiishi et al. 2024, Eqs. 1-9)", r.applied_any(), r.notes);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t s = 0; s < r.steps.size(); ++s) {
    const auto& st = r.steps[s];
    const std::string key = "step" + std::to_string(s + 1);
    t.set_meta(key + "_effect", st.effect);
    t.set_meta(key + "_decision", st.decision);
    t.set_meta(key + "_line", st.line);
    const bool ni = st.decision == "not identifiable";
    const double applied = ni ? nan : (st.decision == "applied" ? 1.0 : 0.0);
    const Eigen::Index k = std::max<Eigen::Index>(1, st.value.size());
    for (Eigen::Index j = 0; j < k; ++j) {
      const bool has = j < st.value.size();
      if (has)
        t.set_meta(key + "_parameter" + std::to_string(j), st.names[static_cast<std::size_t>(j)]);
      t.rows.push_back({static_cast<double>(s + 1), has ? static_cast<double>(j) : nan,
                        has ? st.value(j) : nan, has ? st.u(j) : nan, ni ? nan : st.F,
                        ni ? nan : st.p_value, applied, ni ? nan : st.rms_w_change_um,
                        ni ? nan : st.rms_w_error_left_um, ni ? nan : st.rms_w_error_applied_um,
                        ni ? nan : st.rms_u_w_added_um});
    }
  }
  t.set_meta("steps", std::to_string(r.steps.size()));
  return t;
}

HtmlTable displacement_refine_table(const CsvTable& t, const std::filesystem::path& file) {
  if (t.meta("format") != std::optional<std::string>(kDisplacementRefineFormat))
    throw CsvError(file, 0,
                   std::string("not a displacement refine file ('# format: ") +
                       kDisplacementRefineFormat + "')");
  const auto n = t.meta("steps");
  if (!n) throw CsvError(file, 0, "metadata 'steps' missing");
  HtmlTable out;
  out.id = "displacement_refine";
  out.caption =
      "Closing the loop (displacement method): effects the model lacks, what the redundant "
      "readings show of them, and whether correcting them makes w better; predicted RMS errors of "
      "w in um";
  out.header = {"effect",      "decision",     "size +- u",
                "F, p",        "w changed by", "error of w without -> with it",
                "adds to u(w)"};
  const auto step = t.column("step", file), idx = t.column("parameter_index", file),
             val = t.column("value", file), u = t.column("u", file), F = t.column("F", file),
             p = t.column("p_value", file), chg = t.column("w_change_rms_um", file),
             without = t.column("w_error_without_rms_um", file),
             with = t.column("w_u_if_applied_rms_um", file),
             added = t.column("u_w_added_rms_um", file);
  const int count = std::atoi(n->c_str());
  for (int s = 1; s <= count; ++s) {
    const std::string key = "step" + std::to_string(s);
    const auto effect = t.meta(key + "_effect"), decision = t.meta(key + "_decision");
    if (!effect || !decision) throw CsvError(file, 0, "metadata '" + key + "_effect' missing");
    std::string size, fp, c, ww, a;
    for (std::size_t r = 0; r < step.size(); ++r) {
      if (static_cast<int>(step[r]) != s) continue;
      if (std::isfinite(idx[r])) {
        const auto name =
            t.meta(key + "_parameter" + std::to_string(static_cast<int>(idx[r]))).value_or("p");
        size += (size.empty() ? "" : ", ") + name + " = " + fmt(val[r], "%.4g") + " +- " +
                fmt(u[r], "%.2g");
      }
      fp = std::isfinite(F[r]) ? fmt(F[r]) + ", " + fmt(p[r], "%.2g") : "-";
      c = fmt(chg[r]);
      ww = std::isfinite(without[r]) ? fmt(without[r]) + " -> " + fmt(with[r]) : "-";
      a = fmt(added[r]);
    }
    out.rows.push_back({*effect, *decision, size.empty() ? "-" : size, fp, c, ww, a});
  }
  if (count == 0)
    out.rows.push_back({"nothing taken: the redundant readings show no effect of the library", "-",
                        "-", "-", "-", "-", "-"});
  for (int i = 1;; ++i) {
    const auto note = t.meta("note" + std::to_string(i));
    if (!note) break;
    out.rows.push_back({*note, "note", "", "", "", "", ""});
  }
  return out;
}

}  // namespace errsep::io

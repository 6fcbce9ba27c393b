#include "errsep/io/budget_report.hpp"

#include <algorithm>
#include <cstdio>
#include <sstream>

namespace errsep::io {
namespace {

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

void rows_table(std::ostringstream& s, const core::Budget& b, const char* u_unit) {
  std::size_t w = 6;
  for (const auto& r : b.rows)
    w = std::max(w, r.symbol.size());
  char line[256];
  std::snprintf(line, sizeof line, "  %-*s  %12s  %12s  %12s  %12s  %7s\n", static_cast<int>(w),
                "term", (std::string("u (") + u_unit + ")").c_str(), "sensitivity", "contrib (um)",
                "var (um^2)", "share");
  s << line;
  for (const auto& r : b.rows) {
    std::snprintf(line, sizeof line, "  %-*s  %12.6g  %12.6g  %12.4f  %12.4f  %6.2f%%",
                  static_cast<int>(w), r.symbol.c_str(), r.u, r.sensitivity, r.contribution,
                  r.variance, 100.0 * r.share);
    s << line;
    if (!r.description.empty()) s << "  " << r.description;
    s << "\n";
  }
}

}  // namespace

std::string format_budget_text(const core::BudgetEvaluation& ev, const std::string& title) {
  std::ostringstream s;
  if (!title.empty()) s << title << "\n\n";
  for (const auto& t : ev.thermal) {
    s << "Thermal loop '" << t.name << "' (" << t.symbol << ")";
    if (!t.description.empty()) s << ": " << t.description;
    s << "\n ";
    for (const auto& [g, l] : t.group_length_mm)
      s << " sum s*l(" << g << ") " << fmt("%.6g", l) << " mm,";
    s << " beta " << fmt("%.6g", t.beta_um_per_K) << " um/K, sigma_beta "
      << fmt("%.6g", t.sigma_beta_um_per_K) << " um/K\n";
    rows_table(s, t.budget, "input");
    s << "  " << t.symbol << " = " << fmt("%.4f", t.sigma_um) << " um\n\n";
  }
  s << "Combined budget (" << ev.budget.quantity << "), uncorrelated inputs (GUM law of "
    << "propagation):\n";
  rows_table(s, ev.budget, "um");
  s << "  " << ev.budget.quantity << "^2 = " << fmt("%.4f", ev.budget.variance) << " um^2, "
    << ev.budget.quantity << " = " << fmt("%.4f", ev.budget.combined) << " um (k = 1); "
    << "expanded U = " << fmt("%.2g", 2.0 * ev.budget.combined) << " um (k = 2)\n";
  return s.str();
}

CsvTable budget_csv(const core::BudgetEvaluation& ev, const std::string& title) {
  CsvTable t;
  t.set_meta("errsep", "uncertainty budget");
  if (!title.empty()) t.set_meta("title", title);
  t.set_meta("quantity", ev.budget.quantity);
  t.set_meta("combined_um", fmt("%.10g", ev.budget.combined));
  t.set_meta("variance_um2", fmt("%.10g", ev.budget.variance));
  for (const auto& th : ev.thermal)
    t.set_meta("thermal_" + th.symbol, "sigma " + fmt("%.10g", th.sigma_um) + " um, beta " +
                                           fmt("%.10g", th.beta_um_per_K) + " um/K, sigma_beta " +
                                           fmt("%.10g", th.sigma_beta_um_per_K) + " um/K");
  std::vector<double> idx, u, c, contrib, var, share;
  for (std::size_t i = 0; i < ev.budget.rows.size(); ++i) {
    const auto& r = ev.budget.rows[i];
    t.set_meta("term_" + std::to_string(i + 1),
               r.symbol + (r.description.empty() ? "" : ": " + r.description));
    idx.push_back(double(i + 1));
    u.push_back(r.u);
    c.push_back(r.sensitivity);
    contrib.push_back(r.contribution);
    var.push_back(r.variance);
    share.push_back(100.0 * r.share);
  }
  t.add_column("term_index", idx);
  t.add_column("u_um", u);
  t.add_column("sensitivity", c);
  t.add_column("contribution_um", contrib);
  t.add_column("variance_um2", var);
  t.add_column("share_percent", share);
  return t;
}

}  // namespace errsep::io

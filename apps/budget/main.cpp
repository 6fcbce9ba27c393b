// errsep-budget: evaluates an uncertainty budget config (GUM, uncorrelated inputs; thermal
// expansion model of Haramiishi et al. 2024 Eqs. 30-40; combination of Eq. 41), prints the
// readable table and writes it as CSV and/or text.
#include <CLI/CLI.hpp>
#include <exception>
#include <iostream>

#include "errsep/core/uncertainty_budget.hpp"
#include "errsep/io/atomic_file.hpp"
#include "errsep/io/budget_config.hpp"
#include "errsep/io/budget_report.hpp"
#include "errsep/io/staged_directory.hpp"
#include "errsep/version.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "errsep uncertainty budget: thermal-expansion loops and the combined standard uncertainty "
      "from a TOML config (example: config/budget-haramiishi2024.toml, the paper's Tables 1-2)"};
  app.set_version_flag("--version", std::string(errsep::kVersion));
  std::string config, csv_out, text_out;
  bool no_rounding = false, quiet = false;
  app.add_option("-c,--config", config, "budget config (TOML)")->required();
  app.add_option("--csv", csv_out, "write the budget as CSV (atomically)");
  app.add_option("--text", text_out, "write the readable table to this file (atomically)");
  app.add_flag("--no-rounding", no_rounding,
               "ignore the config's round_sigma_um and combine unrounded values");
  app.add_flag("-q,--quiet", quiet, "do not print the table");
  app.footer(
      "CSV columns: term_index, u_um, sensitivity, contribution_um, variance_um2, share_percent;\n"
      "term names, the combined value and the thermal loops are in '# key: value' metadata.");
  CLI11_PARSE(app, argc, argv);
  try {
    // What a killed earlier run left beside the outputs (its temporaries) goes first.
    if (const auto swept = errsep::io::sweep_beside({csv_out, text_out}); !swept.empty())
      std::cerr << "errsep-budget: " << swept << "\n";
    errsep::core::BudgetSpec spec = errsep::io::read_budget_config(config);
    if (no_rounding) spec.round_sigma_um = 0.0;
    const auto ev = errsep::core::evaluate_budget(spec);
    const std::string text = errsep::io::format_budget_text(ev, spec.title);
    const auto table = errsep::io::budget_csv(ev, spec.title);
    if (!csv_out.empty()) errsep::io::write_csv(csv_out, table);
    if (!text_out.empty()) errsep::io::write_file_atomic(text_out, text);
    if (!quiet) std::cout << text;
  } catch (const std::exception& e) {
    std::cerr << "errsep-budget: " << e.what() << "\n";
    return 1;
  }
  return 0;
}

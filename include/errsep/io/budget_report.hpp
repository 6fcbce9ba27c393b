#pragma once
// Formatting an evaluated uncertainty budget: a readable text table (thermal loops with their
// inputs, then the combined budget with each contribution and its share) and a CSV in errsep's
// convention (numeric columns; term names in "# term_<i>: ..." metadata lines).
#include <string>

#include "errsep/core/uncertainty_budget.hpp"
#include "errsep/io/csv.hpp"

namespace errsep::io {

/// Human-readable report; values in µm, shares in %.
std::string format_budget_text(const core::BudgetEvaluation& ev, const std::string& title);

/// Columns term_index, u_um, sensitivity, contribution_um, variance_um2, share_percent; one row
/// per term of the combined budget; metadata: title, quantity, combined_um, variance_um2,
/// term_<i> = "symbol: description", thermal_<symbol> = σ, β, σ_β of each loop.
CsvTable budget_csv(const core::BudgetEvaluation& ev, const std::string& title);

}  // namespace errsep::io

#pragma once
// Reading an uncertainty-budget config (TOML) into core::BudgetSpec.  Format (all keys checked;
// an unknown key is an error, so a typo cannot silently drop a term):
//
//   title = "..."                 quantity = "sigma_w"       round_sigma_um = 0.0   (optional)
//   [temperature]   change_K = 4.0   uncertainty_K = 2.0   distribution = "uniform"
//   [coefficients.<name>]   alpha_per_K = 23.6e-6   uncertainty_per_K = 1.0e-6
//                           distribution = "uniform"              (default uniform)
//   [components.<name>]     length_mm = 20   tolerance_mm = 0.033   coefficient = "<name>"
//                           distribution = "normal"               (default normal)
//   [[loop]]   name = "x"   symbol = "sigma_tx"   description = "..."
//              components = ["+A", "+B", "-jig_x", "-reference"]   (sign and component name)
//   [[term]]   symbol = "sigma_m2x"   description = "..."   sensitivity = 1.0   (optional)
//              value_um = 0.99   distribution = "normal"     -- or --   thermal_loop = "x"
//
// config/budget-haramiishi2024.toml is the paper's Tables 1 and 2 in this format.
#include <filesystem>
#include <stdexcept>
#include <string>

#include "errsep/core/uncertainty_budget.hpp"
#include "errsep/io/config_error.hpp"

namespace errsep::io {

/// Parses TOML text; `name` is used in error messages as the file name.  Throws ConfigError
/// (config_error.hpp) on a syntax error, a missing or unknown key, a value of the wrong type, or a
/// spec that core::evaluate_budget would reject (unknown component, coefficient or loop).
core::BudgetSpec parse_budget_config(const std::string& toml_text, const std::string& name);

/// Reads and parses a file.  Throws ConfigError (also when the file cannot be opened).
core::BudgetSpec read_budget_config(const std::filesystem::path& file);

}  // namespace errsep::io

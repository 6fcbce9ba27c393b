#pragma once
// The one-axis displacement refine's account (core/displacement_refine_one_axis.hpp) as a CSV,
// refine/displacement_refine.csv of a displacement result set, and as the report's table.
//
//   # format: errsep displacement refine
//   # stepK_effect, stepK_decision ("applied", "detected, not applied", "not identifiable"),
//   # stepK_line (the decision in words), stepK_parameterJ (names); noteN (what was assumed)
//   step, parameter_index, value, u, F, p_value, applied, w_change_rms_um,
//   w_error_without_rms_um, w_u_if_applied_rms_um, u_w_added_rms_um
// One row per parameter of a step (value and u in the parameter's unit, named in its metadata);
// a step the plan cannot identify has one row of nan but its step number.  The w columns are the
// decision's predictions (step_decision.hpp): what the correction changes in w, the estimated
// error of w without it, what applying it adds to u(w), and what the step adds to the refined
// u(w) (all RMS over the points, the constant of w removed where the decision removes it).
#include <filesystem>

#include "errsep/core/displacement_refine_one_axis.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/html_report.hpp"

namespace errsep::io {

inline constexpr const char* kDisplacementRefineFormat = "errsep displacement refine";

CsvTable displacement_refine_csv(const core::OneAxisRefineResult& r);

/// The report's table of a displacement_refine.csv (effect, decision, parameters ± u, w change,
/// error without → with).  Throws CsvError naming `file` when it is not such a file.
HtmlTable displacement_refine_table(const CsvTable& t, const std::filesystem::path& file);

}  // namespace errsep::io

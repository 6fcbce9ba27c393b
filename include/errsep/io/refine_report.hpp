#pragma once
// The refinement loop's step table (core/refine.hpp) as CSV (one row per parameter of each step,
// step-level figures repeated; effect names and the model in metadata) and as readable text.
#include <string>
#include <vector>

#include "errsep/core/refine.hpp"
#include "errsep/core/sequence_refine.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/html_report.hpp"

namespace errsep::io {

/// Columns: step, parameter_index, value, u_value, F, p_value, rms_before_um, rms_after_um,
/// whiteness_p, S_err_before_um, S_err_after_um, gamma_err_before_urad, gamma_err_after_urad,
/// f_err_before_um, f_err_after_um (nan where not applicable).  Metadata: model, stop reason,
/// "step<k>_effect" and "step<k>_parameter<j>" names, "lambda_before" / "lambda_after" (the λ of
/// the separations of the raw and the corrected readings, see lambda_summary).
CsvTable refine_csv(const core::RefineResult& r);
/// The columns of refine_csv, in order.
const std::vector<std::string>& refine_csv_columns();

/// Whose figures a refine_steps.csv concerns (its metadata kRefineRoleKey): the result written
/// beside it, or, on a scan sequence whose refined fit is the result, the single-scan refine of
/// m1..m4 kept for comparison (errsep-report words its warnings by it).
enum class RefineRole { result, comparison };
const char* to_string(RefineRole r);
inline constexpr const char* kRefineRoleKey = "refine_role";
/// The role `steps` states; a table without it (written before the key existed) is the result's.
/// Throws CsvError naming `file` for a value that is neither.
RefineRole refine_role_of(const CsvTable& steps, const std::filesystem::path& file);

/// "λ (rule)" or "λ (rule, fallback)" of a separation, e.g. "0.3481 (lcurve)" or
/// "9.033e-07 (lcurve, no_regularisation)".
std::string lambda_summary(const core::FourSensorResult& sep);

/// The step table, the λ of the separations before and after, the final candidate scores and the
/// whiteness verdict as text.
std::string format_refine_text(const core::RefineResult& r);

/// A refine_steps.csv (refine_csv) read back as a readable table for a report: one row per step
/// with the effect, its parameters (value ± u, k = 1), F and p, the residual RMS before -> after,
/// the errors against the truth before -> after where the run had one, and the verdict.  Throws
/// CsvError naming `file` when a column or a step's metadata is missing.
HtmlTable refine_steps_table(const CsvTable& steps, const std::filesystem::path& file);

/// A scan sequence's refine (core/sequence_refine.hpp) as CSV: columns x_mm, S_before_um,
/// u_S_before_um, S_after_um, u_S_after_um and u_S_after_um's parts in quadrature
/// (u_S_widening_um, u_S_knock_um, u_S_declined_um, u_S_drift_form_um, u_S_hysteresis_um; u at
/// k = 1, S about its best-fit constant, line and bow); metadata "format: errsep sequence refine",
/// plan, added effects, the knock and the hysteresis (hysteresis_um "h +- u" and
/// hysteresis_applied when detected, else "hysteresis: none found" or why the plan cannot show
/// it), and one "finding_<k>" line per finding (an effect identified, ambiguous, or detected and
/// not identifiable from the plan, with what to measure instead).  Throws std::invalid_argument
/// when x_mm does not have one value per position.
CsvTable sequence_refine_csv(const core::SequenceRefineResult& r, const std::vector<double>& x_mm);

/// A sequence_refine.csv read back as the report's table of findings (one row each; a run that
/// found nothing says so).  Throws CsvError naming `file` when it is not such a file.
HtmlTable sequence_findings_table(const CsvTable& t, const std::filesystem::path& file);

}  // namespace errsep::io

#pragma once
// The two-axis displacement refine's account (core/displacement_refine.hpp) as a CSV: what
// errsep-separate-displacement two-axis --refine writes to <out>.refine.csv.  The layout is the
// one-axis account's (io/displacement_refine_csv.hpp: "# format: errsep displacement refine",
// stepK_effect/_decision/_line/_parameterJ, one row per parameter), so the report's table reads
// both, with two more columns for the motion under sensor 0:
//   step, parameter_index, value, u, F, p_value, applied, w_change_rms_um,
//   w_error_without_rms_um, w_u_if_applied_rms_um, u_w_added_rms_um, m_w_change_rms_um,
//   m_w_error_without_rms_um
// What the plan cannot identify is said once per line as noteN; the plan as `plan`.
#include <string>

#include "errsep/core/displacement_refine.hpp"
#include "errsep/io/csv.hpp"

namespace errsep::io {

/// `plan`: the scan order the library was made for (core::TwoAxisScanOrder::plan_name()).
CsvTable displacement_refine_two_axis_csv(const core::DisplacementRefineResult& r,
                                          const std::string& plan);

}  // namespace errsep::io

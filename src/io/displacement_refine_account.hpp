#pragma once
// What the one-axis and two-axis displacement refine accounts share (io/displacement_refine_csv,
// io/displacement_refine_two_axis_csv): the head of the table and its common columns.  Private
// to src/io.
#include <string>
#include <vector>

#include "errsep/io/csv.hpp"
#include "errsep/io/displacement_refine_csv.hpp"

namespace errsep::io::detail {

/// A table with the format, method, applied_any and note1..noteN lines and the columns every
/// account has (step ... u_w_added_rms_um); the caller appends its own columns and rows.
inline CsvTable displacement_refine_account(const std::string& method, bool applied_any,
                                            const std::vector<std::string>& notes) {
  CsvTable t;
  t.set_meta("format", kDisplacementRefineFormat);
  t.set_meta("method", method);
  t.set_meta("applied_any", applied_any ? "true" : "false");
  for (std::size_t i = 0; i < notes.size(); ++i)
    t.set_meta("note" + std::to_string(i + 1), notes[i]);
  t.columns = {"step",
               "parameter_index",
               "value",
               "u",
               "F",
               "p_value",
               "applied",
               "w_change_rms_um",
               "w_error_without_rms_um",
               "w_u_if_applied_rms_um",
               "u_w_added_rms_um"};
  return t;
}

}  // namespace errsep::io::detail

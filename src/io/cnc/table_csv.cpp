#include "errsep/io/cnc/table_csv.hpp"

#include <stdexcept>

#include "errsep/core/machine_axes.hpp"
#include "errsep/io/cnc/cnc_parameters.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/version.hpp"

namespace errsep::io {
namespace {

class TableCsv final : public CompensationWriter {
 public:
  CompensationFormat format() const override { return CompensationFormat::csv; }
  std::string description() const override { return "errsep table CSV: x_mm (machine), comp_um"; }
  const char* suffix() const override { return ".csv"; }
  std::vector<std::pair<std::string, std::string>> parameters() const override {
    return cnc::uniform_table_parameters(0, "none");
  }
  core::UniformTableOptions settings(const CncParameters& params) const {
    const cnc::ParameterReader r(params, parameters(), to_string(format()));
    return cnc::uniform_table_options(r, 0);
  }
  void validate(const CncParameters& params) const override { (void)settings(params); }
  core::CompensationTable make_table(const core::CompensationProfile& profile,
                                     const CncParameters& params) const override {
    return core::make_uniform_table(profile, settings(params));
  }

  std::vector<CncFile> write(const core::CompensationTable& table, const core::MachineAxes& axes,
                             const CncParameters& params, const CncWriteInfo& info) const override {
    (void)settings(params);
    CsvTable t;
    t.set_meta("errsep compensation table", std::string("v") + kVersion);
    t.set_meta("symbol", axes.symbol());
    t.set_meta("input_axis", std::string(1, axes.input_axis));
    t.set_meta("output_axis", std::string(1, axes.output_axis));
    t.set_meta("sign", "comp = -(error), added to the " + std::string(1, axes.output_axis) +
                           " command at machine positions x of " + std::string(1, axes.input_axis));
    if (!info.title.empty()) t.set_meta("source", cnc::one_line(info.title));
    if (!info.accuracy_line.empty()) t.set_meta("accuracy", cnc::one_line(info.accuracy_line));
    t.add_column("x_mm", table.position_mm);
    t.add_column("comp_um", table.comp_um);
    return {{axes.symbol() + "_table.csv", format_csv(t, 12)}};
  }

  ControllerTable read(const std::string& text, const std::string& name) const override {
    const CsvTable t = parse_csv(text, name, {.allow_non_finite = false, .min_rows = 2});
    ControllerTable ct;
    ct.table.position_mm = t.column("x_mm", name);
    ct.table.comp_um = t.column("comp_um", name);
    for (std::size_t i = 1; i < ct.table.points(); ++i)
      if (!(ct.table.position_mm[i] > ct.table.position_mm[i - 1]))
        throw CsvError(name, t.row_line.empty() ? 0 : t.row_line[i], "x_mm must increase");
    ct.input_axis = core::parse_linear_axis(t.meta("input_axis").value_or(""));
    ct.output_axis = core::parse_linear_axis(t.meta("output_axis").value_or(""));
    return ct;
  }
};

}  // namespace

const CompensationWriter& table_csv_writer() {
  static const TableCsv w;
  return w;
}

}  // namespace errsep::io

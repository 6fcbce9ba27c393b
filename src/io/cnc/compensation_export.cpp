#include "errsep/io/cnc/compensation_export.hpp"

#include <algorithm>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "errsep/io/atomic_file.hpp"
#include "errsep/version.hpp"

namespace errsep::io {
namespace {

std::string g(double v, int digits = 3) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  return buf;
}

std::string verdict(double max_um, double U_um) {
  if (!(U_um > 0)) return "U of the measurement not known";
  return max_um <= U_um ? "within U"
                        : "EXCEEDS U: the table does not represent the measurement; allow more "
                          "points or a finer step";
}

}  // namespace

bool CompensationExportOptions::is_valid(std::string* why) const {
  try {
    if (formats.empty()) throw std::invalid_argument("formats: none chosen");
    if (!(coverage_factor > 0)) throw std::invalid_argument("coverage_factor must be > 0");
    for (const auto& [f, p] : parameters)
      compensation_writer(f).validate(p);
  } catch (const std::invalid_argument& e) {
    if (why) *why = e.what();
    return false;
  }
  return true;
}

CompensationExport export_compensation(const core::CompensationProfile& profile,
                                       const CompensationExportOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("compensation export: " + why);
  CompensationExport out;
  out.symbol = profile.axes.symbol();
  out.coverage_factor = opts.coverage_factor;
  for (double u : profile.u_um)
    out.measurement_U_um = std::max(out.measurement_U_um, opts.coverage_factor * u);
  for (const auto f : opts.formats) {
    const CompensationWriter& w = compensation_writer(f);
    const auto it = opts.parameters.find(f);
    const CncParameters params = it == opts.parameters.end() ? CncParameters{} : it->second;
    try {
      ExportedTable t;
      t.format = f;
      t.table = w.make_table(profile, params);
      CncWriteInfo info;
      info.title = opts.title;
      // Pass 1 without the accuracy line, read back, measure; pass 2 says what was measured.
      auto files = w.write(t.table, profile.axes, params, info);
      t.read_back = w.read(files.front().content, files.front().name);
      t.accuracy = core::table_accuracy(profile, t.read_back.table, t.read_back.extra_um);
      t.accuracy_line = "interpolation error of this table against the measurement: max " +
                        g(t.accuracy.max_um) + " um (at " + g(t.accuracy.position_of_max_mm, 6) +
                        " mm), rms " + g(t.accuracy.rms_um) + " um; U of the measurement " +
                        (out.measurement_U_um > 0 ? g(out.measurement_U_um, 2) +
                                                        " um (k = " + g(opts.coverage_factor) + ")"
                                                  : std::string("not known")) +
                        ": " + verdict(t.accuracy.max_um, out.measurement_U_um);
      info.accuracy_line = t.accuracy_line;
      t.files = w.write(t.table, profile.axes, params, info);
      const ControllerTable again = w.read(t.files.front().content, t.files.front().name);
      if (again.table.comp_um != t.read_back.table.comp_um ||
          again.table.position_mm != t.read_back.table.position_mm)
        throw std::logic_error("the table changed when its accuracy line was added");
      out.tables.push_back(std::move(t));
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(std::string(to_string(f)) + ": " + e.what());
    } catch (const std::runtime_error& e) {
      throw std::runtime_error(std::string(to_string(f)) +
                               ": reading back what was written: " + e.what());
    }
  }
  return out;
}

std::string CompensationExport::summary() const {
  std::ostringstream o;
  for (const auto& t : tables) {
    const auto& tb = t.read_back.table;
    o << symbol << " " << to_string(t.format) << ": " << t.files.front().name << ", " << tb.points()
      << " points over " << g(tb.position_mm.front(), 6) << " .. " << g(tb.position_mm.back(), 6)
      << " mm";
    if (t.table.step_mm > 0) o << " (step " << g(t.table.step_mm, 6) << " mm)";
    o << "; interpolation error max " << g(t.accuracy.max_um) << " um, rms " << g(t.accuracy.rms_um)
      << " um";
    if (measurement_U_um > 0) o << " vs U " << g(measurement_U_um, 2) << " um";
    o << ": " << verdict(t.accuracy.max_um, measurement_U_um) << "\n";
  }
  return o.str();
}

CsvTable CompensationExport::accuracy_csv() const {
  CsvTable c;
  c.set_meta("errsep compensation accuracy", std::string("v") + kVersion);
  c.set_meta("symbol", symbol);
  c.set_meta("coverage_factor", g(coverage_factor));
  c.set_meta("columns",
             "format index (order of 'formats'), points, first and last node (machine "
             "mm), step (0: free breakpoints), interpolation error of the table as "
             "read back against the measurement (max, rms), U of the measurement");
  std::string names;
  std::vector<double> idx, points, first, last, step, mx, rms, U;
  for (std::size_t i = 0; i < tables.size(); ++i) {
    const auto& t = tables[i];
    names +=
        (names.empty() ? "" : " ") + std::string(to_string(t.format)) + "=" + t.files.front().name;
    idx.push_back(static_cast<double>(i));
    points.push_back(static_cast<double>(t.read_back.table.points()));
    first.push_back(t.read_back.table.position_mm.front());
    last.push_back(t.read_back.table.position_mm.back());
    step.push_back(t.table.step_mm);
    mx.push_back(t.accuracy.max_um);
    rms.push_back(t.accuracy.rms_um);
    U.push_back(measurement_U_um);
  }
  c.set_meta("formats", names);
  c.add_column("format_index", idx);
  c.add_column("points", points);
  c.add_column("first_mm", first);
  c.add_column("last_mm", last);
  c.add_column("step_mm", step);
  c.add_column("max_error_um", mx);
  c.add_column("rms_error_um", rms);
  c.add_column("U_um", U);
  return c;
}

std::vector<std::filesystem::path> write_compensation_export(const std::filesystem::path& dir,
                                                             const CompensationExport& e) {
  std::filesystem::create_directories(dir);
  std::vector<std::filesystem::path> written;
  for (const auto& t : e.tables)
    for (const auto& f : t.files) {
      write_file_atomic(dir / f.name, f.content);
      written.push_back(dir / f.name);
    }
  write_file_atomic(dir / "accuracy.csv", format_csv(e.accuracy_csv(), 10));
  written.push_back(dir / "accuracy.csv");
  return written;
}

}  // namespace errsep::io

#include "errsep/io/verification_report.hpp"

#include <cmath>
#include <cstdio>
#include <optional>
#include <sstream>

#include "errsep/io/atomic_file.hpp"
#include "errsep/io/machine_axes_metadata.hpp"
#include "errsep/version.hpp"

namespace errsep::io {
namespace {

std::string g(double v, int digits = 10) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  return buf;
}

// "1.23 um +- 0.45 um" with U to two significant digits.
std::string with_u(double v, double U) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "%.3f um \xC2\xB1 %.2g um", v, U);
  return buf;
}

double number(const CsvTable& csv, const std::string& key, const std::filesystem::path& file) {
  const auto v = csv.meta(key);
  if (!v) throw CsvError(file, 0, "verification metadata '" + key + "' missing");
  try {
    return std::stod(*v);
  } catch (const std::exception&) {
    throw CsvError(file, 0, "verification metadata '" + key + "': '" + *v + "' is not a number");
  }
}

}  // namespace

CsvTable verification_csv(const core::VerificationResult& r, const VerificationInfo& info) {
  CsvTable t;
  t.set_meta("errsep verification", std::string("v") + kVersion);
  t.set_meta("symbol", info.symbol);
  t.set_meta("table", info.table_file);
  t.set_meta("before", info.before);
  t.set_meta("coverage_factor", g(info.coverage_factor));
  t.set_meta("reference", "minimum zone (ISO 230-1); U = k u_c, bound over correlations");
  t.set_meta("before_um", g(r.before.straightness_um));
  t.set_meta("before_U_um", g(r.before.uncertainty.expanded));
  t.set_meta("predicted_um", g(r.predicted.straightness_um));
  t.set_meta("predicted_U_um", g(r.predicted.uncertainty.expanded));
  t.set_meta("measured_um", g(r.measured.straightness_um));
  t.set_meta("measured_U_um", g(r.measured.uncertainty.expanded));
  t.set_meta("difference_um", g(r.difference_um));
  t.set_meta("allowed_um", g(r.allowed_um));
  t.set_meta("consistent", r.consistent ? "true" : "false");
  t.set_meta("ratio_measured_to_before", g(r.ratio));
  t.set_meta("pointwise_coverage", g(r.pointwise_coverage));
  t.add_column("x_mm", r.position_mm);
  t.add_column("e_before_um", r.e_before_um);
  t.add_column("u_before_um", r.u_before_um);
  t.add_column("e_predicted_um", r.e_predicted_um);
  t.add_column("e_measured_um", r.e_measured_um);
  t.add_column("u_measured_um", r.u_measured_um);
  return t;
}

std::string verification_text(const core::VerificationResult& r, const VerificationInfo& info) {
  std::ostringstream o;
  o << "measure - compensate - verify, " << info.symbol
    << " (straightness, minimum zone; U with k = " << g(info.coverage_factor, 3) << ")\n";
  o << "  table applied:        " << info.table_file << "\n";
  o << "  first scan:           " << info.before << "\n";
  o << "  before compensation:  " << with_u(r.before.straightness_um, r.before.uncertainty.expanded)
    << "\n";
  o << "  predicted residual:   "
    << with_u(r.predicted.straightness_um, r.predicted.uncertainty.expanded)
    << "  (first scan + the table as the controller applies it)\n";
  o << "  measured residual:    "
    << with_u(r.measured.straightness_um, r.measured.uncertainty.expanded) << "  ("
    << g(100 * r.ratio, 3) << " % of before)\n";
  o << "  measured - predicted: " << g(r.difference_um, 3) << " um, within U_measured + "
    << "U_predicted = " << g(r.allowed_um, 3)
    << " um: " << (r.consistent ? "consistent" : "NOT consistent") << "\n";
  o << "  point by point:       " << g(100 * r.pointwise_coverage, 3) << " % of " << r.points
    << " positions within k sqrt(u_before^2 + u_after^2) of the prediction (line removed)\n";
  return o.str();
}

std::vector<std::filesystem::path> write_verification(const std::filesystem::path& dir,
                                                      const core::VerificationResult& r,
                                                      const VerificationInfo& info) {
  std::filesystem::create_directories(dir);
  write_file_atomic(dir / "verification.csv", format_csv(verification_csv(r, info), 12));
  write_file_atomic(dir / "verification.txt", verification_text(r, info));
  return {dir / "verification.csv", dir / "verification.txt"};
}

core::MachineError read_machine_error(const std::filesystem::path& result_dir,
                                      const core::MachineAxes& fallback, std::string* warning) {
  const std::filesystem::path f = result_dir / "motion.csv";
  const CsvTable t = read_csv(f, {.allow_non_finite = false, .min_rows = 3});
  std::optional<core::MachineAxes> axes;
  try {
    axes = machine_axes_from_metadata(t.metadata);
  } catch (const std::invalid_argument& e) {
    throw CsvError(f, 0, e.what());
  }
  if (!axes) {
    axes = fallback;
    if (warning)
      *warning = f.string() + " does not record where its scan ran; taken as the machine " +
                 "config's axes (slide_start_mm " + g(fallback.slide_start_mm) + ")";
  }
  const std::vector<double> u =
      t.find_column("u_S_um") ? t.column("u_S_um", f) : std::vector<double>{};
  try {
    return core::machine_error(t.column("x_mm", f), t.column("S_um", f), u, *axes);
  } catch (const std::invalid_argument& e) {
    throw CsvError(f, 0, e.what());
  }
}

std::filesystem::path result_dir_of_table(const std::filesystem::path& table) {
  const std::filesystem::path dir = table.parent_path();
  if (dir.filename() == "compensation" && std::filesystem::exists(dir.parent_path() / "motion.csv"))
    return dir.parent_path();
  return {};
}

std::vector<std::pair<std::string, std::string>> verification_rows(
    const CsvTable& csv, const std::filesystem::path& file) {
  const std::string sym = csv.meta("symbol").value_or("?");
  std::vector<std::pair<std::string, std::string>> rows;
  rows.emplace_back("table applied", csv.meta("table").value_or("?"));
  rows.emplace_back(sym + " before compensation",
                    with_u(number(csv, "before_um", file), number(csv, "before_U_um", file)));
  rows.emplace_back(sym + " predicted residual",
                    with_u(number(csv, "predicted_um", file), number(csv, "predicted_U_um", file)));
  rows.emplace_back(sym + " measured residual",
                    with_u(number(csv, "measured_um", file), number(csv, "measured_U_um", file)));
  rows.emplace_back("measured / before",
                    g(100 * number(csv, "ratio_measured_to_before", file), 3) + " %");
  rows.emplace_back(
      "measured - predicted",
      g(number(csv, "difference_um", file), 3) + " um (allowed " +
          g(number(csv, "allowed_um", file), 3) + " um): " +
          (csv.meta("consistent").value_or("false") == "true" ? "consistent" : "NOT consistent"));
  return rows;
}

}  // namespace errsep::io

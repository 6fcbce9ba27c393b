#include "errsep/service/scan_report_job.hpp"

#include <algorithm>
#include <vector>

#include "errsep/io/staged_directory.hpp"
#include "errsep/service/pdf_print.hpp"

namespace errsep::service {

io::ScanReportOptions report_options_from_config(const io::MachineConfig& cfg) {
  io::ScanReportOptions o;
  o.axes = cfg.axes;
  o.compensation = cfg.compensation.profile;
  o.tables_export = cfg.compensation.tables;
  const io::ReportConfig& r = cfg.report;
  o.particulars.machine = !r.machine.empty() ? r.machine : cfg.mqtt ? cfg.mqtt->machine : "";
  o.particulars.operator_name = r.operator_name;
  o.particulars.instrument = r.instrument;
  o.particulars.temperature_c = r.temperature_c;
  o.particulars.straightness_tolerance_um = r.straightness_tolerance_um;
  if (!o.particulars.straightness_tolerance_um && cfg.mqtt &&
      cfg.mqtt->straightness_tolerance_um > 0)
    o.particulars.straightness_tolerance_um = cfg.mqtt->straightness_tolerance_um;
  if (r.pdf) o.pdf_printer = chromium_pdf_printer();
  return o;
}

io::ScanReportOptions result_report_options(const io::MachineConfig& cfg, bool pdf) {
  io::ScanReportOptions o = report_options_from_config(cfg);
  o.output_subdir = kResultReportSubdir;
  if (!pdf) o.pdf_printer = nullptr;
  return o;
}

bool write_result_report_logged(const std::filesystem::path& dir, const io::ScanReportOptions& ro,
                                std::ostream& log) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) return false;
  const std::string name = dir.filename().string();
  // Each line in one write: other threads (the register map, the publisher) log to the same
  // stream, and the journal takes a line's priority from its start.
  const auto line = [&log](const std::string& l) { log << (l + "\n") << std::flush; };
  try {
    const io::ScanReportResult r = io::write_scan_report(dir, ro);
    if (const std::string swept = io::describe_swept(r.swept); !swept.empty())
      line("<4>" + name + ": report: " + swept);
    for (const auto& w : r.warnings)
      line("<4>" + name + ": report: " + w);
    std::string done = "<6>" + name + ": report: " + r.html.string();
    if (!r.pdf.empty())
      done += ", " + r.pdf.string();
    else if (!r.pdf_skipped.empty())
      done += " (PDF skipped: " + r.pdf_skipped + ")";
    if (!r.verdict.empty()) done += "; conformance: " + r.verdict;
    line(done);
    return true;
  } catch (const std::exception& e) {
    line("<3>" + name + ": the report failed: " + e.what() + "; the scan's results are kept in " +
         dir.string() + " (errsep-report " + dir.string() + " --subdir " + kResultReportSubdir +
         " makes the report again)");
    return false;
  }
}

int remake_missing_reports(const std::filesystem::path& results_dir,
                           const io::ScanReportOptions& ro, std::ostream& log) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(results_dir, ec)) return 0;
  std::vector<fs::path> dirs;
  for (const auto& e : fs::directory_iterator(results_dir, ec))
    if (e.is_directory(ec)) dirs.push_back(e.path());
  std::sort(dirs.begin(), dirs.end());  // store stems sort by time
  int made = 0;
  for (const fs::path& dir : dirs) {
    if (fs::exists(dir / kResultReportSubdir, ec)) continue;
    if (!fs::exists(dir / "motion.csv", ec) && !fs::exists(dir / "displacement.csv", ec)) continue;
    const io::ResultSetCheck check = io::check_result_set(dir);
    if (!check.has_manifest || check.kind != "scan" || !check.whole()) continue;
    log << ("<5>" + dir.filename().string() +
            ": report missing (the daemon stopped after the scan's results were committed, "
            "before its report): making it now\n")
        << std::flush;
    if (write_result_report_logged(dir, ro, log)) ++made;
  }
  return made;
}

void print_report_outcome(const io::ScanReportResult& r, const std::filesystem::path& dir,
                          std::ostream& out, std::ostream& err) {
  if (const std::string swept = io::describe_swept(r.swept); !swept.empty()) out << swept << "\n";
  out << r.text;
  for (const auto& w : r.warnings)
    err << "warning: " << w << "\n";
  if (!r.compensation_summary.empty())
    out << "compensation tables (" << (r.html.parent_path() / "compensation").string() << "/):\n"
        << r.compensation_summary;
  out << "wrote " << r.written.size() << " files into " << dir.string() << "\n";
  out << "report: " << r.html.string() << "\n";
  if (!r.pdf.empty())
    out << "report (PDF): " << r.pdf.string() << "\n";
  else if (!r.pdf_skipped.empty())
    out << "report (PDF): skipped: " << r.pdf_skipped << "\n";
  out << "  open it with: xdg-open " << r.html.string() << "   (or file://"
      << std::filesystem::absolute(r.html).lexically_normal().string() << " in a browser)\n";
}

}  // namespace errsep::service

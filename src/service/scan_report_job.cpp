#include "errsep/service/scan_report_job.hpp"

#include "errsep/io/staged_directory.hpp"

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
  o.pdf = r.pdf;
  return o;
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

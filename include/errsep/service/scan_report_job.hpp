#pragma once
// The report of a result set, as errsep-scan makes it after every scan (OUT/report/) and
// errsep-report makes it on demand: the machine config's settings turned into report options
// once, and what was written said once.
#include <filesystem>
#include <ostream>

#include "errsep/io/machine_config.hpp"
#include "errsep/io/scan_report.hpp"

namespace errsep::service {

/// The report options a machine config gives: its [axes] (for results that do not record where
/// the scan ran), [compensation] (line removed, formats, parameters) and [report] (particulars,
/// tolerance, PDF), with [mqtt] machine and straightness_tolerance_um as defaults for the
/// machine's name and the tolerance.
io::ScanReportOptions report_options_from_config(const io::MachineConfig& cfg);

/// The sub-folder of a result set that receives the report made after each scan.
inline constexpr const char* kResultReportSubdir = "report";

/// The options of the report errsep-scan and errsep-daemon make after each scan into
/// DIR/report/: report_options_from_config with the sub-folder set, the PDF only when both
/// `[report] pdf` and `pdf` (errsep-scan's --no-pdf) allow it.
io::ScanReportOptions result_report_options(const io::MachineConfig& cfg, bool pdf = true);

/// errsep-daemon's report after each scan: when `dir` is a result folder (none after a scan
/// without separation, or whose separation failed), makes `dir`/report/ (io::write_scan_report,
/// staged as a set of its own: a kill leaves the scan's results as they were) and logs one line
/// per outcome to `log` with the journal's priority prefixes (<6> where the report is, <4> its
/// warnings, <3> why it failed).  A failed report changes none of the scan's files; it is
/// reported and never thrown.  Returns true when a report was written.
bool write_result_report_logged(const std::filesystem::path& dir, const io::ScanReportOptions& ro,
                                std::ostream& log);

/// errsep-daemon at start-up: each result folder in `results_dir` (a whole result set of kind
/// "scan" holding a separation: motion.csv or displacement.csv) without its report/ -- the daemon
/// was stopped after the folder was committed and before its report was made -- gets the report
/// now (write_result_report_logged), with a <5> journal line saying why.  Returns how many
/// reports were made.  Never throws for a folder: what fails is logged.
int remake_missing_reports(const std::filesystem::path& results_dir,
                           const io::ScanReportOptions& ro, std::ostream& log);

/// Prints the evaluation, the warnings (to `err`), the compensation tables, where report.html and
/// report.pdf are (or why no PDF was made) and how to open the report.
void print_report_outcome(const io::ScanReportResult& r, const std::filesystem::path& dir,
                          std::ostream& out, std::ostream& err);

}  // namespace errsep::service

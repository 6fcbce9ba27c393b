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

/// Prints the evaluation, the warnings (to `err`), the compensation tables, where report.html and
/// report.pdf are (or why no PDF was made) and how to open the report.
void print_report_outcome(const io::ScanReportResult& r, const std::filesystem::path& dir,
                          std::ostream& out, std::ostream& err);

}  // namespace errsep::service

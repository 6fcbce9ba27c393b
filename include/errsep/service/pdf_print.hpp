#pragma once
// A PDF of the HTML report, printed by headless Chromium (Debian's `chromium`): the page a
// customer receives, as the browser lays it out (the report's print style sheet breaks before
// the appendix).  Chromium runs with a new, empty profile folder, no network services and no
// sandbox (it may run as root in a service or a container), and is killed after a time-out.
// Nothing here is real-time safe; it forks a process.
#include <filesystem>
#include <string>

#include "errsep/io/scan_report.hpp"

namespace errsep::service {

struct PdfOptions {
  std::string chromium = "chromium";  ///< program name (searched in PATH) or path
  double timeout_s = 90;              ///< Chromium is killed after this long
  bool is_valid(std::string* why) const;
};

/// Prints `html` (a local file) to `pdf`.  Never throws for a missing or failing Chromium: the
/// outcome says why no PDF was written (the HTML report stands on its own).
io::PdfOutcome print_html_to_pdf(const std::filesystem::path& html,
                                 const std::filesystem::path& pdf, const PdfOptions& opts = {});

/// The report's printer (io::ScanReportOptions::pdf_printer): print_html_to_pdf with `opts`.
/// Throws std::invalid_argument naming the field when `opts` is not valid.
io::PdfPrinter chromium_pdf_printer(const PdfOptions& opts = {});

}  // namespace errsep::service

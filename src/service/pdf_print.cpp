#include "errsep/service/pdf_print.hpp"

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <system_error>

#include "errsep/io/child_process.hpp"

namespace errsep::service {
namespace fs = std::filesystem;

bool PdfOptions::is_valid(std::string* why) const {
  if (chromium.empty()) {
    if (why) *why = "chromium: the program name is empty";
    return false;
  }
  if (!(timeout_s > 0)) {
    if (why) *why = "timeout_s = " + std::to_string(timeout_s) + " must be > 0";
    return false;
  }
  return true;
}

io::PdfOutcome print_html_to_pdf(const fs::path& html, const fs::path& pdf,
                                 const PdfOptions& opts) {
  io::PdfOutcome out;
  std::string why;
  if (!opts.is_valid(&why)) {
    out.why_not = "PdfOptions: " + why;
    return out;
  }
  // A new, empty profile for every run: no state of an earlier run or of a user's browser.
  std::string tmpl = (fs::temp_directory_path() / "errsep-chromium-XXXXXX").string();
  if (!::mkdtemp(tmpl.data())) {
    out.why_not =
        "cannot create a profile folder for Chromium in " + fs::temp_directory_path().string();
    return out;
  }
  const fs::path profile = tmpl;
  const fs::path log = profile / "chromium.log";
  io::ChildRun run;
  run.argv = {opts.chromium,
              "--headless",
              "--no-sandbox",
              "--disable-gpu",
              "--disable-quic",
              "--no-first-run",
              "--disable-background-networking",
              "--disable-component-update",
              "--disable-sync",
              "--user-data-dir=" + profile.string(),
              "--no-pdf-header-footer",
              "--print-to-pdf=" + fs::absolute(pdf).string(),
              "file://" + fs::absolute(html).string()};
  run.log = log;
  run.timeout_s = opts.timeout_s;
  std::error_code ec;
  fs::remove(pdf, ec);
  const int rc = io::run_child(run, &why);
  std::string tail;
  {
    std::ifstream in(log);
    std::stringstream ss;
    ss << in.rdbuf();
    tail = ss.str();
    if (tail.size() > 400) tail = "..." + tail.substr(tail.size() - 400);
  }
  fs::remove_all(profile, ec);
  if (rc < 0) {
    out.why_not = why + (why.find("cannot run") != std::string::npos
                             ? " (apt-get install chromium, or give its path)"
                             : "");
    return out;
  }
  if (rc != 0 || !fs::exists(pdf) || fs::file_size(pdf, ec) == 0) {
    out.why_not = "'" + opts.chromium + "' exited with status " + std::to_string(rc) +
                  " and wrote no PDF: " + tail;
    fs::remove(pdf, ec);
    return out;
  }
  out.written = true;
  return out;
}

io::PdfPrinter chromium_pdf_printer(const PdfOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("ScanReportOptions: pdf_print: " + why);
  return [opts](const fs::path& html, const fs::path& pdf) {
    return print_html_to_pdf(html, pdf, opts);
  };
}

}  // namespace errsep::service

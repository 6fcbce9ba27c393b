#pragma once
// One self-contained HTML page per scan: no external files, scripts or fonts.  PNG figures are
// embedded as base64 data URIs, SVG figures inline; every text is HTML-escaped.
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace errsep::io {

struct HtmlTable {
  std::string id;  ///< HTML id of the <table> (e.g. "evaluation")
  std::string caption;
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
};

struct HtmlFigure {
  std::string caption;
  std::filesystem::path image;  ///< .png (embedded as base64) or .svg (inlined)
  bool appendix = false;        ///< a diagnostic (L-curve, residuals): shown in the appendix
};

struct HtmlReport {
  std::string title;
  /// The measurement as a report for a customer states it, in order: date and time, machine,
  /// axis, operator, instrument and sensor, temperature, software, standard, tolerance ...
  /// ("not stated" where the inputs did not say).
  std::vector<std::pair<std::string, std::string>> measurement;
  /// The conformance statement when a tolerance is given (e.g. "PASS: ..."); empty = none.
  std::string verdict;
  std::string raw_data_file;  ///< the raw scan the results came from ("unknown" if not known)
  std::string result_dir;
  std::vector<std::pair<std::string, std::string>> configuration;  ///< metadata, in order
  std::vector<HtmlTable> tables;  ///< evaluation first; refine steps etc.
  std::vector<HtmlFigure> figures;
  std::vector<std::pair<std::string, std::string>> files;  ///< written files: name, description
  std::vector<std::string> notes;  ///< warnings and the statements of method
  std::string generated_by;        ///< e.g. "errsep-report 0.1.0"
};

/// Escapes &, <, >, " and '.
std::string html_escape(const std::string& s);
/// RFC 4648 base64.
std::string base64_encode(const std::string& bytes);

/// The page as a string.  Throws std::runtime_error if a figure file cannot be read.
std::string render_html_report(const HtmlReport& report);

}  // namespace errsep::io

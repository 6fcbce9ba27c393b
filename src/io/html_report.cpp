#include "errsep/io/html_report.hpp"

#include <fstream>
#include <sstream>
#include <stdexcept>

namespace errsep::io {
namespace {

std::string read_bytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) throw std::runtime_error("report: cannot read figure " + p.string());
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// An SVG from gnuplot starts with an XML declaration and a DOCTYPE, which are not allowed inside
// HTML: keep from "<svg" on.
std::string inline_svg(const std::string& svg) {
  const auto pos = svg.find("<svg");
  if (pos == std::string::npos) throw std::runtime_error("report: SVG without <svg> element");
  return svg.substr(pos);
}

const char* kStyle = R"(
body { font-family: "DejaVu Sans", Arial, sans-serif; margin: 24px; color: #222; max-width: 1100px; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; }
h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; padding-bottom: 2px; margin-top: 1.6em; }
table { border-collapse: collapse; margin: 8px 0 16px 0; font-size: 0.92em; }
th, td { border: 1px solid #bbb; padding: 3px 8px; text-align: left; vertical-align: top; }
th { background: #eef2f7; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
caption { caption-side: top; text-align: left; font-weight: bold; padding: 4px 0; }
figure { margin: 12px 0 20px 0; }
figure img, figure svg { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #444; }
.meta { color: #555; font-size: 0.9em; }
.note { background: #fff8e1; border-left: 4px solid #f0b400; padding: 4px 8px; margin: 4px 0; }
code { background: #f4f4f4; padding: 0 3px; }
.verdict { font-size: 1.15em; font-weight: bold; padding: 6px 10px; margin: 8px 0; border: 2px solid; }
.verdict.pass { color: #1b5e20; border-color: #2e7d32; background: #e8f5e9; }
.verdict.fail { color: #b71c1c; border-color: #c62828; background: #ffebee; }
.verdict.open { color: #6d4c00; border-color: #f0b400; background: #fff8e1; }
@media print {
  body { margin: 0; max-width: none; font-size: 10pt; }
  h2 { break-after: avoid; }
  figure, table { break-inside: avoid; }
  .appendix { break-before: page; }
}
)";

// Right-align cells that start with a number ("12.3", "-0.5 ± 0.1"), not "-" or text.
bool numeric_like(const std::string& s) {
  std::size_t i = 0;
  if (i < s.size() && (s[i] == '-' || s[i] == '+')) ++i;
  if (i < s.size() && s[i] == '.') ++i;
  return i < s.size() && s[i] >= '0' && s[i] <= '9';
}

}  // namespace

std::string html_escape(const std::string& s) {
  std::string out;
  out.reserve(s.size());
  for (char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string base64_encode(const std::string& bytes) {
  static const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  const auto* b = reinterpret_cast<const unsigned char*>(bytes.data());
  for (; i + 2 < bytes.size(); i += 3) {
    const unsigned v = (b[i] << 16) | (b[i + 1] << 8) | b[i + 2];
    out += t[(v >> 18) & 63];
    out += t[(v >> 12) & 63];
    out += t[(v >> 6) & 63];
    out += t[v & 63];
  }
  if (i + 1 == bytes.size()) {
    const unsigned v = b[i] << 16;
    out += t[(v >> 18) & 63];
    out += t[(v >> 12) & 63];
    out += "==";
  } else if (i + 2 == bytes.size()) {
    const unsigned v = (b[i] << 16) | (b[i + 1] << 8);
    out += t[(v >> 18) & 63];
    out += t[(v >> 12) & 63];
    out += t[(v >> 6) & 63];
    out += '=';
  }
  return out;
}

std::string render_html_report(const HtmlReport& r) {
  std::ostringstream o;
  o << "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n";
  o << "<title>" << html_escape(r.title) << "</title>\n<style>" << kStyle << "</style>\n";
  o << "</head>\n<body>\n";
  o << "<h1>" << html_escape(r.title) << "</h1>\n";
  o << "<p class=\"meta\">Raw data: <code id=\"raw-data\">" << html_escape(r.raw_data_file)
    << "</code>";
  if (!r.result_dir.empty())
    o << " &middot; results: <code>" << html_escape(r.result_dir) << "</code>";
  if (!r.generated_by.empty()) o << " &middot; " << html_escape(r.generated_by);
  o << "</p>\n";

  // numbers_right: right-align cells that read as numbers (result tables, not key-value lists).
  auto table = [&](const HtmlTable& t, bool numbers_right = true) {
    o << "<table";
    if (!t.id.empty()) o << " id=\"" << html_escape(t.id) << "\"";
    o << ">\n";
    if (!t.caption.empty()) o << "<caption>" << html_escape(t.caption) << "</caption>\n";
    o << "<thead><tr>";
    for (const auto& h : t.header)
      o << "<th>" << html_escape(h) << "</th>";
    o << "</tr></thead>\n<tbody>\n";
    for (const auto& row : t.rows) {
      o << "<tr>";
      for (const auto& c : row)
        o << (numbers_right && numeric_like(c) ? "<td class=\"num\">" : "<td>") << html_escape(c)
          << "</td>";
      o << "</tr>\n";
    }
    o << "</tbody>\n</table>\n";
  };

  // A section of key-value rows (the measurement's particulars, the configuration).
  auto pairs = [&](const char* heading, const char* id, std::vector<std::string> header,
                   const std::vector<std::pair<std::string, std::string>>& kv) {
    if (kv.empty()) return;
    o << "<h2>" << heading << "</h2>\n";
    HtmlTable t;
    t.id = id;
    t.header = std::move(header);
    for (const auto& [k, v] : kv)
      t.rows.push_back({k, v});
    table(t, false);
  };
  pairs("Measurement", "measurement", {"item", "value"}, r.measurement);
  if (!r.verdict.empty()) {
    const char* cls = r.verdict.rfind("PASS", 0) == 0   ? "pass"
                      : r.verdict.rfind("FAIL", 0) == 0 ? "fail"
                                                        : "open";
    o << "<div id=\"verdict\" class=\"verdict " << cls << "\">" << html_escape(r.verdict)
      << "</div>\n";
  }

  for (std::size_t i = 0; i < r.tables.size(); ++i) {
    if (i == 0) o << "<h2>Evaluation</h2>\n";
    if (i == 1) o << "<h2>Further tables</h2>\n";
    table(r.tables[i]);
  }

  auto figures = [&](bool appendix) {
    for (const auto& f : r.figures) {
      if (f.appendix != appendix) continue;
      o << "<figure>\n";
      const std::string ext = f.image.extension().string();
      const std::string bytes = read_bytes(f.image);
      if (ext == ".svg") {
        o << inline_svg(bytes) << "\n";
      } else if (ext == ".png") {
        o << "<img alt=\"" << html_escape(f.caption) << "\" src=\"data:image/png;base64,"
          << base64_encode(bytes) << "\">\n";
      } else {
        throw std::runtime_error("report: figure " + f.image.string() + " is neither PNG nor SVG");
      }
      o << "<figcaption>" << html_escape(f.caption) << "</figcaption>\n</figure>\n";
    }
  };
  const auto any = [&](bool appendix) {
    for (const auto& f : r.figures)
      if (f.appendix == appendix) return true;
    return false;
  };
  if (any(false)) {
    o << "<h2>Figures</h2>\n";
    figures(false);
  }
  // Warnings and the statements of method, after the results they qualify.
  if (!r.notes.empty()) {
    o << "<h2>Notes</h2>\n";
    for (const auto& n : r.notes)
      o << "<div class=\"note\">" << html_escape(n) << "</div>\n";
  }
  // Diagnostics of the separation (L-curve, residuals): for the metrologist, after the results.
  if (any(true)) {
    o << "<h2 class=\"appendix\">Appendix: diagnostics of the separation</h2>\n";
    figures(true);
  }

  pairs("Configuration", "configuration", {"key", "value"}, r.configuration);

  if (!r.files.empty()) {
    o << "<h2>Files</h2>\n<ul>\n";
    for (const auto& [name, what] : r.files)
      o << "<li><code>" << html_escape(name) << "</code> &mdash; " << html_escape(what)
        << "</li>\n";
    o << "</ul>\n";
  }
  o << "</body>\n</html>\n";
  return o.str();
}

}  // namespace errsep::io

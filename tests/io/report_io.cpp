// Building blocks of the report: uncertainty formatting, HTML escaping and embedding, gnuplot.
#include <catch2/catch.hpp>
#include <fstream>
#include <sstream>

#include "errsep/io/html_report.hpp"
#include "errsep/io/plots.hpp"
#include "errsep/io/scan_report.hpp"
#include "support/support.hpp"

using namespace errsep::io;

namespace {
std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}
}  // namespace

TEST_CASE("value +- U: U to two significant digits (rounded up), value to the same place") {
  CHECK(format_value_with_uncertainty(24.2809, 2.51) == "24.3 \xC2\xB1 2.6");
  CHECK(format_value_with_uncertainty(690.04, 7.95) == "690.0 \xC2\xB1 8.0");
  CHECK(format_value_with_uncertainty(1.23456, 0.0123) == "1.235 \xC2\xB1 0.013");
  CHECK(format_value_with_uncertainty(5.0, 0.996) == "5.0 \xC2\xB1 1.0");
  CHECK(format_value_with_uncertainty(1234.6, 56.1) == "1235 \xC2\xB1 57");
  CHECK(format_value_with_uncertainty(12.0, 0.0) == "12 \xC2\xB1 \xE2\x80\x94");
}

TEST_CASE("base64 matches the RFC 4648 test vectors, and HTML text is escaped") {
  CHECK(base64_encode("") == "");
  CHECK(base64_encode("f") == "Zg==");
  CHECK(base64_encode("fo") == "Zm8=");
  CHECK(base64_encode("foo") == "Zm9v");
  CHECK(base64_encode("foob") == "Zm9vYg==");
  CHECK(base64_encode("fooba") == "Zm9vYmE=");
  CHECK(base64_encode("foobar") == "Zm9vYmFy");
  CHECK(base64_encode(std::string("\xff\x00\x80", 3)) == "/wCA");
  CHECK(html_escape("<a href=\"x\">&'</a>") == "&lt;a href=&quot;x&quot;&gt;&amp;&#39;&lt;/a&gt;");

  errsep::test::TempDir tmp;
  std::ofstream(tmp / "f.svg")
      << "<?xml version=\"1.0\"?>\n<!DOCTYPE svg>\n<svg width=\"10\"></svg>\n";
  HtmlReport r;
  r.title = "scan <script>alert(1)</script>";
  r.raw_data_file = "raw & co.csv";
  r.tables.push_back({"evaluation", "cap", {"a", "b"}, {{"EYX", "1.5 \xC2\xB1 0.1"}}});
  r.figures.push_back({"a figure", tmp / "f.svg"});
  const std::string html = render_html_report(r);
  CHECK_THAT(html, !Catch::Contains("<script>"));
  CHECK_THAT(html, Catch::Contains("scan &lt;script&gt;"));
  CHECK_THAT(html, Catch::Contains("raw &amp; co.csv"));
  CHECK_THAT(html, Catch::Contains("<svg width=\"10\"></svg>"));
  CHECK_THAT(html, !Catch::Contains("<?xml"));
  CHECK_THAT(html, Catch::Contains("<td class=\"num\">1.5"));
  r.figures = {{"missing", tmp / "nope.png"}};
  CHECK_THROWS_WITH(render_html_report(r), Catch::Contains("nope.png"));
}

TEST_CASE("gnuplot draws PNG and SVG line plots and heat maps") {
  REQUIRE(gnuplot_available());  // gnuplot-nox is in cmake/debian-packages.txt
  errsep::test::TempDir tmp;
  LinePlot p;
  p.name = "t_line";
  p.title = "S_x with under_scores & 'quotes'";
  p.xlabel = "x / mm";
  p.ylabel = "S / \xC2\xB5m";
  p.series.push_back({"S", {0, 1, 2, 3}, {0, 1, 0, -1}, {0.1, 0.1, 0.2, 0.2}});
  p.marker = std::pair{1.0, 1.0};
  p.marker_label = "corner";
  const auto f = render_line_plot(p, tmp.path(), {});
  const std::string png = slurp(f.png);
  CHECK(png.compare(0, 8, "\x89PNG\r\n\x1a\n") == 0);
  CHECK_THAT(slurp(f.svg), Catch::Contains("<svg"));
  CHECK(std::filesystem::exists(f.script));
  CHECK_FALSE(std::filesystem::exists(tmp / "t_line.log"));

  HeatMap m;
  m.name = "t_map";
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 4; ++i)
      m.x.push_back(i), m.y.push_back(j), m.z.push_back(i * j);
  CHECK(std::filesystem::exists(render_heat_map(m, tmp.path(), {}).png));
  m.x.pop_back(), m.y.pop_back(), m.z.pop_back();
  CHECK_THROWS_WITH(render_heat_map(m, tmp.path(), {}), Catch::Contains("not a rectangular grid"));

  p.name = "../escape";
  CHECK_THROWS_AS(render_line_plot(p, tmp.path(), {}), std::invalid_argument);
  PlotOptions bad;
  bad.gnuplot = "/nonexistent/gnuplot";
  p.name = "t2";
  CHECK_FALSE(gnuplot_available(bad));
  CHECK_THROWS_WITH(render_line_plot(p, tmp.path(), bad), Catch::Contains("cannot run"));
}

TEST_CASE("conformance with a tolerance: ISO 14253-1, the uncertainty counts against the claim") {
  using errsep::io::conformance_verdict;
  // Well inside, well outside, straddling on either side of the tolerance, U unknown.
  CHECK(conformance_verdict(6.0, 1.0, 10.0).rfind("PASS: ", 0) == 0);
  CHECK(conformance_verdict(9.0, 1.0, 10.0).rfind("PASS: ", 0) == 0);  // 9 + 1 = 10: still in
  CHECK(conformance_verdict(12.0, 1.0, 10.0).rfind("FAIL: ", 0) == 0);
  CHECK(conformance_verdict(9.5, 1.0, 10.0).rfind("NOT PROVEN: ", 0) == 0);
  CHECK(conformance_verdict(10.5, 1.0, 10.0).rfind("NOT PROVEN: ", 0) == 0);
  CHECK(conformance_verdict(11.0, 1.0, 10.0).rfind("NOT PROVEN: ", 0) == 0);  // 11 - 1 = 10
  CHECK(conformance_verdict(2.0, 0.0, 10.0).rfind("NOT PROVEN: ", 0) == 0);
  CHECK_THAT(conformance_verdict(2.0, 0.0, 10.0), Catch::Contains("not known"));
  CHECK_THAT(conformance_verdict(6.0, 1.0, 10.0), Catch::Contains("10 um"));
}

TEST_CASE("the measurement, the verdict, and the diagnostics in an appendix after the results") {
  errsep::test::TempDir tmp;
  const auto svg = tmp / "f.svg";
  std::ofstream(svg) << "<?xml version=\"1.0\"?><svg xmlns=\"http://www.w3.org/2000/svg\"></svg>";
  HtmlReport r;
  r.title = "t";
  r.measurement = {{"Machine", "M1 <hall 2>"}, {"Operator", "not stated"}};
  r.verdict = "FAIL: 12 um exceeds the tolerance 10 um";
  r.figures = {{"the L-curve", svg, true}, {"S(x)", svg, false}};
  const std::string h = render_html_report(r);
  const auto measurement = h.find("<table id=\"measurement\">");
  const auto verdict = h.find("<div id=\"verdict\" class=\"verdict fail\">");
  const auto results = h.find("<figcaption>S(x)</figcaption>");
  const auto appendix = h.find("Appendix: diagnostics");
  const auto lcurve = h.find("<figcaption>the L-curve</figcaption>");
  REQUIRE(measurement != std::string::npos);
  REQUIRE(verdict != std::string::npos);
  REQUIRE(results != std::string::npos);
  REQUIRE(appendix != std::string::npos);
  REQUIRE(lcurve != std::string::npos);
  CHECK(measurement < verdict);
  CHECK(verdict < results);
  CHECK(results < appendix);
  CHECK(appendix < lcurve);
  CHECK_THAT(h, Catch::Contains("M1 &lt;hall 2&gt;"));
  CHECK_THAT(h, Catch::Contains("@media print"));
}

#include "errsep/io/plots.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>

#include "errsep/io/atomic_file.hpp"
#include "errsep/io/child_process.hpp"
#include "errsep/io/csv.hpp"

namespace errsep::io {
namespace {

// gnuplot single-quoted string: no escapes except '' for a quote.
std::string q(const std::string& s) {
  std::string out = "'";
  for (char c : s) {
    if (c == '\'')
      out += "''";
    else if (c == '\n' || c == '\r')
      out += ' ';
    else
      out += c;
  }
  return out + "'";
}

// Text for enhanced-mode titles: escape the characters gnuplot's enhanced text treats as markup.
std::string enh(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '_' || c == '^' || c == '@' || c == '&' || c == '~' || c == '{' || c == '}')
      out += '\\';
    out += c;
  }
  return q(out);
}

void check_name(const std::string& name) {
  if (name.empty() || name.find('/') != std::string::npos || name.find('\0') != std::string::npos)
    throw std::invalid_argument("plot name '" + name + "' must be a plain file stem");
}

std::string read_text(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Runs `gnuplot script` in the script's folder (the script names its files relative to it, so
// that it runs from where it is written, whatever the folder is called later: a report is drawn
// in a staging folder and moved into place) with stdout/stderr to `log`; returns the exit status
// (-1: not started).
int run_gnuplot(const std::string& program, const std::filesystem::path& script,
                const std::filesystem::path& log, std::string* err) {
  ChildRun run;
  run.argv = {program, script.filename().string()};
  run.cwd = script.has_parent_path() ? script.parent_path() : std::filesystem::path(".");
  run.log = log;
  return run_child(run, err);
}

std::string terminals(const PlotOptions& o, const PlotFiles& f, const std::string& body) {
  std::ostringstream s;
  if (o.png) {
    s << "set terminal pngcairo size " << o.width_px << "," << o.height_px
      << " enhanced font 'sans,10'\n";
    s << "set output " << q(f.png.filename().string()) << "\n" << body << "unset output\n";
  }
  if (o.svg) {
    s << "set terminal svg size " << o.width_px << "," << o.height_px
      << " enhanced font 'sans,10' background '#ffffff'\n";
    s << "set output " << q(f.svg.filename().string()) << "\n" << body << "unset output\n";
  }
  return s.str();
}

PlotFiles run(const std::string& name, const std::filesystem::path& dir, const PlotOptions& o,
              const std::string& data, const std::string& body) {
  std::string why;
  if (!o.is_valid(&why)) throw std::invalid_argument("PlotOptions: " + why);
  std::filesystem::create_directories(dir);
  PlotFiles f;
  f.data = dir / (name + ".dat");
  f.script = dir / (name + ".gp");
  if (o.png) f.png = dir / (name + ".png");
  if (o.svg) f.svg = dir / (name + ".svg");
  write_file_atomic(f.data, data);
  std::string script = "# errsep figure '" + name + "': run `gnuplot " + name + ".gp`\n";
  script += "set encoding utf8\n";
  script += "datafile = " + q(f.data.filename().string()) + "\n";
  script += terminals(o, f, body);
  write_file_atomic(f.script, script);
  const auto log = dir / (name + ".log");
  std::string err;
  const int rc = run_gnuplot(o.gnuplot, f.script, log, &err);
  if (rc != 0) {
    const std::string msg = rc < 0 ? err : read_text(log);
    throw std::runtime_error("gnuplot failed on " + f.script.string() + ": " + msg);
  }
  std::error_code ec;
  std::filesystem::remove(log, ec);
  for (const auto& p : {f.png, f.svg})
    if (!p.empty() && !std::filesystem::exists(p))
      throw std::runtime_error("gnuplot did not write " + p.string());
  return f;
}

}  // namespace

bool PlotOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (gnuplot.empty()) return fail("gnuplot program name is empty");
  if (width_px < 100 || width_px > 10000 || height_px < 100 || height_px > 10000)
    return fail("size " + std::to_string(width_px) + "x" + std::to_string(height_px) +
                " px must be within 100..10000");
  if (!png && !svg) return fail("neither png nor svg requested");
  return true;
}

bool gnuplot_available(const PlotOptions& opts) {
  char tmpl[] = "/tmp/errsep-gnuplot-XXXXXX";
  const int fd = mkstemp(tmpl);
  if (fd < 0) return false;
  const char probe[] = "exit\n";
  const bool wrote = ::write(fd, probe, sizeof probe - 1) == static_cast<ssize_t>(sizeof probe - 1);
  ::close(fd);
  std::string err;
  const int rc = wrote ? run_gnuplot(opts.gnuplot, tmpl, "/dev/null", &err) : -1;
  ::unlink(tmpl);
  return rc == 0;
}

PlotFiles render_line_plot(const LinePlot& p, const std::filesystem::path& dir,
                           const PlotOptions& opts) {
  check_name(p.name);
  if (p.series.empty()) throw std::invalid_argument("plot '" + p.name + "': no series");
  std::ostringstream data;
  for (std::size_t k = 0; k < p.series.size(); ++k) {
    const Series& s = p.series[k];
    if (s.x.size() != s.y.size() || (!s.band.empty() && s.band.size() != s.y.size()))
      throw std::invalid_argument("plot '" + p.name + "', series '" + s.title +
                                  "': x, y (and band) must have the same length");
    data << "# " << s.title << "\n";
    for (std::size_t i = 0; i < s.x.size(); ++i)
      data << format_number(s.x[i]) << " " << format_number(s.y[i]) << " "
           << format_number(s.band.empty() ? 0.0 : s.band[i]) << "\n";
    data << "\n\n";  // next gnuplot data set (index)
  }
  static const char* colours[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd",
                                  "#ff7f0e", "#8c564b", "#17becf", "#7f7f7f"};
  std::ostringstream b;
  b << "set title " << enh(p.title) << "\n";
  b << "set xlabel " << enh(p.xlabel) << "\nset ylabel " << enh(p.ylabel) << "\n";
  b << "set grid\nset key outside right top\n";
  b << (p.log_x ? "set logscale x\n" : "unset logscale x\n");
  b << (p.log_y ? "set logscale y\n" : "unset logscale y\n");
  b << "unset label\n";
  if (p.marker) {
    b << "set label 1 " << enh(p.marker_label) << " at " << format_number(p.marker->first) << ","
      << format_number(p.marker->second) << " point pt 7 ps 1.5 lc rgb '#d62728' offset 1,1\n";
  }
  b << "plot ";
  bool first = true;
  for (std::size_t k = 0; k < p.series.size(); ++k) {
    const Series& s = p.series[k];
    const std::string c = s.colour.empty() ? colours[k % 8] : s.colour;
    if (!s.band.empty()) {
      b << (first ? "" : ", \\\n     ") << "datafile index " << k
        << " using 1:($2-$3):($2+$3) with filledcurves fc rgb '" << c
        << "' fs transparent solid 0.25 noborder title " << enh(s.title + " \xC2\xB1U (k=2)");
      first = false;
    }
    b << (first ? "" : ", \\\n     ") << "datafile index " << k << " using 1:2 with "
      << (s.points   ? "points pt 7 ps 0.5"
          : s.dashed ? "lines lw 1.5 dt 2"
                     : "lines lw 2")
      << " lc rgb '" << c << "' "
      << (s.title.empty() ? std::string("notitle") : "title " + enh(s.title));
    first = false;
  }
  b << "\n";
  return run(p.name, dir, opts, data.str(), b.str());
}

PlotFiles render_heat_map(const HeatMap& m, const std::filesystem::path& dir,
                          const PlotOptions& opts) {
  check_name(m.name);
  if (m.x.size() != m.y.size() || m.x.size() != m.z.size() || m.x.empty())
    throw std::invalid_argument("heat map '" + m.name +
                                "': x, y, z must be non-empty, same length");
  // Sort into rows of constant y (gnuplot's grid format: blank line between scan lines).
  std::map<double, std::map<double, double>> rows;
  for (std::size_t i = 0; i < m.x.size(); ++i)
    rows[m.y[i]][m.x[i]] = m.z[i];
  const std::size_t nx = rows.begin()->second.size();
  for (const auto& [y, r] : rows)
    if (r.size() != nx)
      throw std::invalid_argument(
          "heat map '" + m.name + "': not a rectangular grid (row y = " + format_number(y) +
          " has " + std::to_string(r.size()) + " nodes, expected " + std::to_string(nx) + ")");
  std::ostringstream data;
  for (const auto& [y, r] : rows) {
    for (const auto& [x, z] : r)
      data << format_number(x) << " " << format_number(y) << " " << format_number(z) << "\n";
    data << "\n";
  }
  std::ostringstream b;
  b << "set title " << enh(m.title) << "\n";
  b << "set xlabel " << enh(m.xlabel) << "\nset ylabel " << enh(m.ylabel) << "\n";
  b << "set cblabel " << enh(m.cblabel) << "\n";
  b << "set palette defined (0 '#313695', 0.25 '#74add1', 0.5 '#ffffbf', 0.75 '#f46d43', 1 "
       "'#a50026')\n";
  b << "set view map\nset autoscale fix\nunset key\n";
  b << "plot datafile using 1:2:3 with image\n";
  return run(m.name, dir, opts, data.str(), b.str());
}

}  // namespace errsep::io

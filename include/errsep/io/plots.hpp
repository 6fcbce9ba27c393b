#pragma once
// Figures for the reports, drawn by gnuplot.
//
// Why gnuplot: it is a well-kept plotting program packaged by Debian (gnuplot-nox, no X needed),
// it writes PNG (pngcairo) and SVG from the same script, and driving it through a script file
// keeps errsep free of a plotting library in C++: we write the data and a .gp script next to the
// figures (so a user can re-run or restyle them) and run `gnuplot script.gp`.  Nothing here is
// real-time safe; it forks a process.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace errsep::io {

struct PlotOptions {
  std::string gnuplot = "gnuplot";  ///< program name (searched in PATH) or path
  int width_px = 900;
  int height_px = 480;
  bool png = true;
  bool svg = true;
  bool is_valid(std::string* why) const;
};

/// One curve.  When `band` is set (same size as y) a shaded band y +- band is drawn behind it.
struct Series {
  std::string title;
  std::vector<double> x, y;
  std::vector<double> band;
  bool points = false;   ///< draw points instead of a line
  bool dashed = false;   ///< a thin dashed line (reference lines, zone limits)
  std::string colour{};  ///< "#rrggbb"; empty = the next colour of the palette
};

struct LinePlot {
  std::string name;  ///< file stem: <name>.png, <name>.svg, <name>.gp, <name>.dat
  std::string title, xlabel, ylabel;
  std::vector<Series> series;
  bool log_x = false, log_y = false;
  /// A marked point (e.g. the L-curve corner) with its label.
  std::optional<std::pair<double, double>> marker;
  std::string marker_label;
};

/// Scalar field on a rectangular grid of nodes (any order; every (x, y) once).
struct HeatMap {
  std::string name;
  std::string title, xlabel, ylabel, cblabel;
  std::vector<double> x, y, z;
};

struct PlotFiles {
  std::filesystem::path png, svg, script, data;
};

/// True when the gnuplot program can be run.
bool gnuplot_available(const PlotOptions& opts = {});

/// Writes <dir>/<name>.dat and .gp, runs gnuplot, returns the files.  Throws std::runtime_error
/// with gnuplot's message (from <dir>/<name>.log) if it fails, std::invalid_argument on bad input.
PlotFiles render_line_plot(const LinePlot& plot, const std::filesystem::path& dir,
                           const PlotOptions& opts = {});
PlotFiles render_heat_map(const HeatMap& map, const std::filesystem::path& dir,
                          const PlotOptions& opts = {});

}  // namespace errsep::io

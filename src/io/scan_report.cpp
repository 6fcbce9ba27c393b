#include "errsep/io/scan_report.hpp"
#include "errsep/io/straightness_trend.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <tuple>

#include "errsep/io/atomic_file.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/displacement_refine_csv.hpp"
#include "errsep/io/four_sensor_result_csv.hpp"
#include "errsep/io/html_report.hpp"
#include "errsep/io/machine_axes_metadata.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "errsep/io/refine_report.hpp"
#include "errsep/io/staged_directory.hpp"
#include "errsep/io/verification_report.hpp"
#include "errsep/version.hpp"

namespace errsep::io {
namespace fs = std::filesystem;
namespace {

using core::ReferenceLine;
using core::ReferencePlane;

std::string sig(double v, int digits = 4) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  return buf;
}

char upper_axis(char c, const char* what) {
  const char u = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  if (u != 'X' && u != 'Y' && u != 'Z')
    throw std::invalid_argument(std::string(what) + " '" + std::string(1, c) +
                                "' is not X, Y or Z");
  return u;
}

std::vector<double> optional_column(const CsvTable& t, const std::string& name) {
  if (!t.find_column(name)) return {};
  return t.column(name);
}

bool all_zero(const std::vector<double>& v) {
  return std::all_of(v.begin(), v.end(), [](double d) { return d == 0.0; });
}

std::vector<double> scaled(const std::vector<double>& v, double k) {
  std::vector<double> o(v);
  for (auto& d : o)
    d *= k;
  return o;
}

struct Row {  // one line of the evaluation table
  std::string symbol, quantity, reference, csv_name, unit;
  double value = 0, expanded = 0;  // expanded <= 0: not known
};

struct MotionData {
  fs::path file;
  CsvTable table;
  std::vector<double> x, s, u_s, gamma_urad, u_gamma;
};

struct GridData {
  fs::path file;
  CsvTable table;
  std::vector<double> x, y, w, m, u_w;
  std::string m_column;
};

// Files of a result set that are not a displacement grid or profile: not read in the search for
// one (the refine step table has nan cells, which only its own reader accepts).
bool is_other_result_file(const std::string& stem) {
  for (const char* known :
       {"motion", "reference", "lcurve", "residuals", "evaluation", "refine_steps",
        "refine_residual", "reference_comparison", "verification", "trend", "displacement_refine"})
    if (stem == known) return true;
  return false;
}

std::optional<GridData> find_grid(const fs::path& dir, const fs::path& given) {
  std::vector<fs::path> candidates;
  if (!given.empty()) {
    candidates.push_back(given);
  } else {
    for (const auto& e : fs::directory_iterator(dir))
      if (e.is_regular_file() && e.path().extension() == ".csv") candidates.push_back(e.path());
    std::sort(candidates.begin(), candidates.end());
  }
  for (const auto& p : candidates) {
    const std::string stem = p.stem().string();
    if (is_other_result_file(stem)) continue;
    CsvTable t = read_csv(p);
    if (!t.find_column("x_mm") || !t.find_column("y_mm") || !t.find_column("w_um")) {
      if (!given.empty()) throw CsvError(p, 1, "grid CSV needs columns x_mm, y_mm, w_um");
      continue;
    }
    GridData g;
    g.file = p;
    g.x = t.column("x_mm", p);
    g.y = t.column("y_mm", p);
    g.w = t.column("w_um", p);
    for (const char* mc : {"m_um", "m_w_um"})
      if (t.find_column(mc)) {
        g.m = t.column(mc, p);
        g.m_column = mc;
        break;
      }
    g.u_w = optional_column(t, "u_w_um");
    g.table = std::move(t);
    return g;
  }
  return std::nullopt;
}

// U rounded up to two significant digits (GUM 7.2.6; rounding up keeps it conservative).
double round_up_2sig(double u) {
  if (!(u > 0) || !std::isfinite(u)) return u;
  const int exp10 = static_cast<int>(std::floor(std::log10(u)));
  const double scale = std::pow(10.0, 1 - exp10);
  return std::ceil(u * scale - 1e-9) / scale;
}

// One-axis displacement result (Haramiishi 2024 Eqs. 1-9): x_mm, m_um, w_um [, r_um], no y_mm.
struct ProfileData {
  fs::path file;
  CsvTable table;
  std::vector<double> x, m, w, u_m, u_w;
};

std::optional<ProfileData> find_one_axis(const fs::path& dir) {
  std::vector<fs::path> candidates;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file() && e.path().extension() == ".csv") candidates.push_back(e.path());
  std::sort(candidates.begin(), candidates.end());
  for (const auto& p : candidates) {
    const std::string stem = p.stem().string();
    if (is_other_result_file(stem)) continue;
    CsvTable t = read_csv(p);
    if (!t.find_column("x_mm") || t.find_column("y_mm") || !t.find_column("m_um") ||
        !t.find_column("w_um"))
      continue;
    ProfileData d;
    d.file = p;
    d.x = t.column("x_mm", p);
    d.m = t.column("m_um", p);
    d.w = t.column("w_um", p);
    d.u_m = optional_column(t, "u_m_um");
    d.u_w = optional_column(t, "u_w_um");
    d.table = std::move(t);
    return d;
  }
  return std::nullopt;
}

std::string text_table(const std::vector<Row>& rows, double k) {
  std::ostringstream o;
  char buf[256];
  std::snprintf(buf, sizeof buf, "%-6s %-40s %-20s %14s %12s  %s\n", "ISO", "quantity", "reference",
                "value", "U (k=2)", "unit");
  o << buf;
  for (const auto& r : rows) {
    std::snprintf(buf, sizeof buf, "%-6s %-40s %-20s %14s %12s  %s\n", r.symbol.c_str(),
                  r.quantity.c_str(), r.reference.c_str(), sig(r.value, 6).c_str(),
                  r.expanded > 0 ? sig(round_up_2sig(r.expanded), 2).c_str() : "-", r.unit.c_str());
    o << buf;
  }
  o << "U: expanded uncertainty, coverage factor k = " << k << "\n";
  return o.str();
}

// A refine step's file: DIR is its result (errsep-refine --out, OUT/refine), or a scan's set
// holds it in refine/ (errsep-scan --refine).  The path found, relative to dir (none: empty).
fs::path find_refine_file(const fs::path& dir, const std::string& name) {
  for (const fs::path& rel : {fs::path(name), fs::path("refine") / name})
    if (fs::exists(dir / rel)) return rel;
  return {};
}

// Where the report's page links a file of dir (the page is written into output_subdir when set).
fs::path linked_from_report(const ScanReportOptions& opts, const fs::path& rel) {
  return (opts.output_subdir.empty() ? fs::path() : fs::path("..")) / rel;
}

}  // namespace

bool ReportParticulars::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (temperature_c &&
      !(std::isfinite(*temperature_c) && *temperature_c > -50 && *temperature_c < 100))
    return fail("temperature_c = " + sig(*temperature_c) + " must be in (-50, 100) degC");
  if (straightness_tolerance_um &&
      !(std::isfinite(*straightness_tolerance_um) && *straightness_tolerance_um > 0))
    return fail("straightness_tolerance_um = " + sig(*straightness_tolerance_um) + " must be > 0");
  return true;
}

std::string conformance_verdict(double value, double U, double tolerance) {
  const std::string t = sig(tolerance) + " um";
  if (!(U > 0) || !std::isfinite(U))
    return "NOT PROVEN: " + sig(value) + " um against the tolerance " + t +
           ", but its uncertainty is not known (ISO 14253-1 needs U to decide)";
  const std::string vu = sig(value) + " um (U = " + sig(round_up_2sig(U), 2) + " um, k = 2)";
  if (value + U <= tolerance)
    return "PASS: " + vu + " is within the tolerance " + t + " including its uncertainty " +
           "(ISO 14253-1)";
  if (value - U > tolerance)
    return "FAIL: " + vu + " exceeds the tolerance " + t + " beyond its uncertainty " +
           "(ISO 14253-1)";
  return "NOT PROVEN: " + vu + " straddles the tolerance " + t +
         " within its uncertainty: neither conformance nor non-conformance is proven (ISO " +
         "14253-1); a better measurement can decide";
}

bool ScanReportOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  std::string w;
  if (!particulars.is_valid(&w)) return fail("particulars: " + w);
  if (output_subdir.find('/') != std::string::npos || output_subdir == "." || output_subdir == "..")
    return fail("output_subdir '" + output_subdir + "' must be one folder name");
  if (!evaluation.is_valid(&w)) return fail("evaluation: " + w);
  if (tables && !tables_export.is_valid(&w)) return fail("compensation tables: " + w);
  if (axes && !axes->is_valid(&w)) return fail("axes: " + w);
  if (plots && !plot.is_valid(&w)) return fail("plot: " + w);
  if (local_length_mm < 0 || !std::isfinite(local_length_mm))
    return fail("local_length_mm = " + std::to_string(local_length_mm) + " must be >= 0");
  if (u_w_um < 0 || !std::isfinite(u_w_um))
    return fail("u_w_um = " + std::to_string(u_w_um) + " must be >= 0");
  for (char c : {axis, direction})
    if (c != 0 && std::string("XYZxyz").find(c) == std::string::npos)
      return fail(std::string("axis '") + c + "' is not X, Y or Z");
  return true;
}

std::string format_value_with_uncertainty(double value, double u) {
  if (!(u > 0) || !std::isfinite(u)) return sig(value, 4) + " \xC2\xB1 \xE2\x80\x94";
  // Two significant digits of U (rounded up) decide the decimal place.
  const double ur = round_up_2sig(u);
  const int exp10 = static_cast<int>(std::floor(std::log10(ur) + 1e-12));
  const int decimals = std::max(0, 1 - exp10);
  char buf[96];
  std::snprintf(buf, sizeof buf, "%.*f \xC2\xB1 %.*f", decimals, value, decimals, ur);
  return buf;
}

ScanReportResult write_scan_report(const fs::path& dir, const ScanReportOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("ScanReportOptions: " + why);
  if (!fs::is_directory(dir))
    throw std::runtime_error(dir.string() + ": not a directory (expected a result directory)");
  ScanReportResult res;
  // The report, figures and tables become part of the result set: the set is checked whole
  // (refused otherwise, naming what is missing), its files are linked into a staging folder
  // beside DIR, the outputs written there, and the whole set moved into place at the end
  // (io/staged_directory.hpp): a kill leaves the earlier set, never a report of another run.
  std::vector<std::string> replaced = {"evaluation.csv", "evaluation.txt", "report.html", "plots",
                                       "compensation"};
  if (!opts.output_subdir.empty()) replaced = {opts.output_subdir};
  StagedDirectory stage(
      dir, {"result", std::string("errsep-report ") + kVersion, true, std::move(replaced)});
  res.swept = stage.swept();
  const fs::path out = opts.output_subdir.empty() ? stage.dir() : stage.dir() / opts.output_subdir;
  if (!fs::exists(dir / kManifestName))
    res.warnings.push_back(dir.string() + " has no " + kManifestName +
                           " (written by hand or by an older errsep): its files cannot be "
                           "checked to be whole and of one run.");
  for (const auto& e : check_result_set(dir).extra)
    res.warnings.push_back(e + " is not part of the result set of " + dir.string() +
                           " (added after its run): used as found.");
  // Raw scans of the set are read as every reader of raw scans reads them (plausibility of each
  // reading, position and time), incomplete ones included.
  RawReadOptions inspect;
  inspect.require_complete = false;
  std::vector<std::pair<std::string, std::string>> raw_meta;  // when and with what it was measured
  if (fs::exists(dir / "raw.csv"))
    raw_meta = read_raw_four_sensor_csv(dir / "raw.csv", inspect).metadata;
  if (fs::exists(dir / "raw_displacement.csv")) {
    auto meta = read_raw_displacement_csv(dir / "raw_displacement.csv", inspect).metadata;
    if (raw_meta.empty()) raw_meta = std::move(meta);  // a displacement scan's own date, machine
  }
  const double k = opts.evaluation.coverage_factor;
  std::vector<Row> rows;
  HtmlReport html;
  html.result_dir = fs::absolute(dir).lexically_normal().string();
  const auto raw_value = [&](const std::string& key) -> std::optional<std::string> {
    for (const auto& [name, value] : raw_meta)
      if (name == key) return value;
    return std::nullopt;
  };
  std::string axis_line = "not recorded";  // the moving axis and the direction evaluated
  // The straightness of S (minimum zone) with U: what a tolerance is checked against.
  std::optional<std::pair<double, double>> mz_straightness;
  html.generated_by = std::string("errsep-report ") + kVersion;
  html.raw_data_file = "unknown (no '# source:' metadata)";
  const fs::path plot_dir = out / "plots";
  bool plots = opts.plots;
  if (plots && !gnuplot_available(opts.plot)) {
    plots = false;
    res.warnings.push_back("gnuplot ('" + opts.plot.gnuplot +
                           "') cannot be run: the report has no figures (apt-get install "
                           "gnuplot-nox).");
  }
  const fs::path comp_dir = out / "compensation";
  std::vector<HtmlFigure> figures;
  CsvTable eval_csv;
  eval_csv.set_meta("errsep evaluation", std::string("v") + kVersion);
  eval_csv.set_meta("coverage_factor", sig(k));
  eval_csv.set_meta("correlation", core::to_string(opts.evaluation.correlation));
  // Every CSV of a set names the run that wrote it (the set's manifest lists this run as one that
  // extended the set).
  eval_csv.set_meta("run_id", stage.run_id());
  const auto with_run_id = [&](CsvTable t) {
    t.set_meta("run_id", stage.run_id());
    return t;
  };
  auto add_eval = [&](const Row& r) {
    rows.push_back(r);
    eval_csv.add_column(r.csv_name + "_" + r.unit, {r.value});
    // Unknown U is an empty field: 0 would read as a perfectly known value.
    eval_csv.add_column(r.csv_name + "_U_" + r.unit,
                        {r.expanded > 0 ? r.expanded : std::numeric_limits<double>::quiet_NaN()});
  };
  // Figures are drawn after every input has been read and evaluated, so a bad input file stops
  // the run before anything is written.
  std::vector<std::pair<LinePlot, std::string>> line_jobs;
  std::vector<std::pair<HeatMap, std::string>> map_jobs;
  std::vector<std::pair<bool, std::size_t>> figure_order;  // (is_map, index)
  auto plot_line = [&](const LinePlot& p, const std::string& caption) {
    if (!plots) return;
    figure_order.emplace_back(false, line_jobs.size());
    line_jobs.emplace_back(p, caption);
  };
  auto plot_map = [&](const HeatMap& m, const std::string& caption) {
    if (!plots) return;
    figure_order.emplace_back(true, map_jobs.size());
    map_jobs.emplace_back(m, caption);
  };
  // Files to write last, so that nothing is written when evaluation fails half-way.
  std::vector<std::pair<fs::path, std::string>> outputs;

  // ---- four-sensor result -------------------------------------------------------------------
  const fs::path motion_file = dir / "motion.csv";
  if (fs::exists(motion_file)) {
    res.four_sensor = true;
    MotionData md;
    md.file = motion_file;
    md.table = read_csv(motion_file, {.allow_non_finite = false, .min_rows = 2});
    md.x = md.table.column("x_mm", motion_file);
    md.s = md.table.column("S_um", motion_file);
    md.u_s = optional_column(md.table, "u_S_um");
    if (md.table.find_column("gamma_urad"))
      md.gamma_urad = md.table.column("gamma_urad", motion_file);
    else if (md.table.find_column("gamma_deg"))
      md.gamma_urad = scaled(md.table.column("gamma_deg", motion_file), core::kUradPerDeg);
    md.u_gamma = optional_column(md.table, "u_gamma_urad");
    for (std::size_t i = 1; i < md.x.size(); ++i)
      if (!(md.x[i] > md.x[i - 1]))
        throw CsvError(motion_file, md.table.row_line.empty() ? 0 : md.table.row_line[i],
                       "x_mm must be strictly increasing");
    for (const auto& [key, v] : md.table.metadata)
      html.configuration.emplace_back(key, v);
    if (auto src = md.table.meta("source")) html.raw_data_file = *src;
    const char axis =
        upper_axis(opts.axis ? opts.axis : md.table.meta("axis").value_or("X").c_str()[0], "axis");
    const char dirn = upper_axis(
        opts.direction ? opts.direction
                       : md.table.meta("straightness_direction").value_or("Y").c_str()[0],
        "straightness direction");
    if (axis == dirn)
      throw std::invalid_argument("axis and straightness direction are both " +
                                  std::string(1, axis));
    const std::string es = core::straightness_symbol(axis, dirn);
    const std::string ea = core::angular_symbol(axis, dirn);
    html.title =
        "errsep scan report: " + es + " / " + ea + " of the " + std::string(1, axis) + " slideway";
    axis_line = std::string(1, axis) + " slideway: straightness in " + std::string(1, dirn) + " (" +
                es + "), angular deviation " + ea;
    if (md.u_s.empty() || all_zero(md.u_s))
      res.warnings.push_back(
          "motion.csv gives no u_S_um (or only zeros): straightness "
          "uncertainties are not available (shown as \xE2\x80\x94).");

    // The separation writes its straightness with U from its own covariance (and the noise's
    // bias of max − min removed); a result without them falls back to the per-point bound.
    bool from_covariance = false;
    for (const auto ref :
         {ReferenceLine::end_points, ReferenceLine::least_squares, ReferenceLine::minimum_zone}) {
      const std::string key = std::string("straightness_") + core::to_string(ref);
      const auto v = md.table.meta_number(key + "_um", motion_file);
      const auto U = md.table.meta_number(key + "_U_um", motion_file);
      if (v && U && opts.evaluation.coverage_factor == 2.0) {
        add_eval({es, "straightness S(x)", core::label(ref), es + "_" + core::to_string(ref), "um",
                  *v, *U});
        if (ref == ReferenceLine::minimum_zone) mz_straightness = {*v, *U};
        from_covariance = true;
        continue;
      }
      const auto r = core::evaluate_straightness(md.x, md.s, md.u_s, ref, opts.evaluation);
      if (ref == ReferenceLine::minimum_zone)
        mz_straightness = {r.straightness_um, r.uncertainty.expanded};
      add_eval({es, "straightness S(x)", core::label(ref), es + "_" + core::to_string(ref), "um",
                r.straightness_um, r.uncertainty.expanded});
    }
    if (from_covariance)
      html.configuration.emplace_back(
          "straightness U",
          "from the separation's posterior covariance (correlations included), "
          "bias of max - min from noise removed (Monte Carlo)");
    const double travel = md.x.back() - md.x.front();
    const double local = opts.local_length_mm > 0 ? opts.local_length_mm : travel / 4;
    // A window must hold two samples: on a short scan (2-4 points) the default travel / 4 is
    // shorter than the sample step; that leaves the local figure out, not the whole report.
    double min_step = travel;
    for (std::size_t i = 1; i < md.x.size(); ++i)
      min_step = std::min(min_step, md.x[i] - md.x[i - 1]);
    const double eps = 1e-9 * std::max(1.0, travel);
    const std::string which = opts.local_length_mm > 0 ? "" : " (the default, travel / 4)";
    if (local + eps < min_step) {
      res.warnings.push_back("local length " + sig(local) + " mm" + which +
                             " is shorter than the sample step " + sig(min_step) + " mm of " +
                             std::to_string(md.x.size()) +
                             " points: local straightness not evaluated (give --local-length "
                             "of at least one step).");
    } else if (local <= travel + eps) {
      const auto r = core::evaluate_local_straightness(md.x, md.s, md.u_s, local,
                                                       opts.local_reference, opts.evaluation);
      add_eval({es, "local straightness over " + sig(local) + " mm",
                core::label(opts.local_reference), es + "_local", "um", r.straightness_um,
                r.uncertainty.expanded});
      eval_csv.add_column("local_length_mm", {local});
    } else {
      res.warnings.push_back("local length " + sig(local) + " mm" + which + " exceeds the travel " +
                             sig(travel) + " mm: local straightness not evaluated.");
    }
    if (!md.gamma_urad.empty()) {
      // A scan sequence's result writes the figure with U from its covariance of γ
      // (service/sequence_result.cpp): max - min cancels γ's constant there, which a fitted
      // warm-up of configuration 4 leaves all but undetermined.  Otherwise U is propagated
      // pointwise from u_gamma_urad.
      const auto v = md.table.meta_number(kMetaAngularDeviationUrad, motion_file);
      const auto U = md.table.meta_number(kMetaAngularDeviationUUrad, motion_file);
      const bool from_cov = v && U && opts.evaluation.coverage_factor == 2.0;
      const auto a = core::evaluate_angular_deviation(md.gamma_urad, md.u_gamma, opts.evaluation);
      const double dev_urad = from_cov ? *v : a.deviation_urad;
      const double U_urad = from_cov ? *U : a.uncertainty.expanded;
      add_eval({ea, "angular deviation gamma(x)", "max - min", ea, "urad", dev_urad, U_urad});
      add_eval({ea, "angular deviation gamma(x)", "max - min", ea, "arcsec",
                dev_urad * core::kArcsecPerUrad, U_urad * core::kArcsecPerUrad});
      if (from_cov)
        html.configuration.emplace_back(
            "angular deviation U", "from the fit's covariance of gamma (correlations included)");
      // An older result whose γ level is undetermined and that has no figure from the
      // covariance: u_gamma_urad (the e4 = 0 gauge's) carries the level at every point, and the
      // pointwise propagation of max - min cannot cancel it: U is overstated, not measured.
      if (!from_cov &&
          md.table.meta(kMetaGammaLevelDetermined) == std::optional<std::string>("false"))
        res.warnings.push_back(
            "gamma's level is not determined by this scan plan with the effects applied: the "
            "angular deviation's U (from u_gamma_urad in the e4 = 0 gauge) is overstated; "
            "gamma's u about its best-fit constant and line is " +
            md.table.meta(kMetaUGammaShapeUrad).value_or("?") + " urad RMS (motion.csv).");
    } else {
      res.warnings.push_back("motion.csv has no gamma_urad/gamma_deg column: no angular figure.");
    }

    // Reference profile f(x) (the artefact, not the machine).
    std::vector<double> fx, f, uf;
    if (fs::exists(dir / "reference.csv")) {
      const auto t = read_csv(dir / "reference.csv", {.allow_non_finite = false, .min_rows = 2});
      fx = t.column("x_mm", dir / "reference.csv");
      f = t.column("f_um", dir / "reference.csv");
      uf = optional_column(t, "u_f_um");
      const auto r =
          core::evaluate_straightness(fx, f, uf, ReferenceLine::minimum_zone, opts.evaluation);
      add_eval({"-", "reference profile f(x) straightness",
                core::label(ReferenceLine::minimum_zone), "f_minimum_zone", "um", r.straightness_um,
                r.uncertainty.expanded});
    }

    // Figures.
    {
      LinePlot p;
      p.name = "straightness";
      p.title = es + ": straightness S(x) of the " + std::string(1, axis) + " slideway in " +
                std::string(1, dirn);
      p.xlabel = "x / mm";
      p.ylabel = "S / \xC2\xB5m";
      p.series.push_back({"S(x)", md.x, md.s, md.u_s.empty() ? md.u_s : scaled(md.u_s, k)});
      // The reference lines of ISO 230-1 the figures are taken about: the least-squares line,
      // and the minimum zone as its two parallel lines (mid-line ± half the zone).
      const auto ls = core::evaluate_straightness(md.x, md.s, {}, ReferenceLine::least_squares,
                                                  opts.evaluation);
      const auto mz =
          core::evaluate_straightness(md.x, md.s, {}, ReferenceLine::minimum_zone, opts.evaluation);
      auto line_series = [&](const std::string& title, const core::Line& l, double shift) {
        const std::vector<double> ends = {md.x.front(), md.x.back()};
        Series ser{title, ends, {l.at(ends[0]) + shift, l.at(ends[1]) + shift}, {}};
        ser.dashed = true;
        ser.colour = shift == 0 ? "#2ca02c" : "#7f7f7f";
        return ser;
      };
      p.series.push_back(line_series("least-squares reference line", ls.line, 0));
      p.series.push_back(line_series("minimum zone (" + sig(mz.straightness_um, 3) + " um)",
                                     mz.line, mz.straightness_um / 2));
      p.series.push_back(line_series("", mz.line, -mz.straightness_um / 2));
      // A band of U = 0.06 um is a line's width on a 40 um plot: say its size in the key, and
      // draw U(x) itself in the next figure.
      if (!md.u_s.empty())
        p.series[0].title =
            "S(x) (max U = " + sig(k * *std::max_element(md.u_s.begin(), md.u_s.end()), 2) + " um)";
      plot_line(p, es + ": S(x) with its expanded uncertainty band (k = " + sig(k) +
                       "), the least-squares reference line and the minimum-zone band");
    }
    if (!md.u_s.empty() && !all_zero(md.u_s)) {
      LinePlot p;
      p.name = "uncertainty";
      p.title = "Expanded uncertainty U(x) = k u(x) of the profiles (k = " + sig(k) + ")";
      p.xlabel = "x / mm";
      p.ylabel = "U / \xC2\xB5m";
      p.series.push_back({"U of S(x)", md.x, scaled(md.u_s, k), {}});
      if (!uf.empty()) p.series.push_back({"U of f(x)", fx, scaled(uf, k), {}});
      plot_line(p, "Expanded uncertainty of S(x) and f(x) at each point (k = " + sig(k) +
                       "; the bands of the profile figures, drawn on their own scale)");
    }
    if (!md.gamma_urad.empty()) {
      LinePlot p;
      p.name = "tilt";
      p.title = ea + ": tilt gamma(x)";
      p.xlabel = "x / mm";
      p.ylabel = "γ / \xC2\xB5rad";
      p.series.push_back({"gamma(x)", md.x, md.gamma_urad,
                          md.u_gamma.empty() ? md.u_gamma : scaled(md.u_gamma, k)});
      plot_line(p, ea + ": tilt gamma(x) in urad with its expanded uncertainty band");
    }
    if (!f.empty()) {
      LinePlot p;
      p.name = "reference";
      p.title = "Reference surface profile f(x)";
      p.xlabel = "x / mm";
      p.ylabel = "f / \xC2\xB5m";
      p.series.push_back({"f(x)", fx, f, uf.empty() ? uf : scaled(uf, k)});
      plot_line(p, "Reference profile f(x) with its expanded uncertainty band");
    }
    if (fs::exists(dir / "residuals.csv")) {
      const auto t = read_csv(dir / "residuals.csv");
      const auto rx = t.column("x_mm", dir / "residuals.csv");
      const auto rc = t.column("config", dir / "residuals.csv");
      const auto rr = t.column("residual_um", dir / "residuals.csv");
      std::map<double, Series> by_config;
      for (std::size_t i = 0; i < rx.size(); ++i) {
        auto& s = by_config[rc[i]];
        s.title = "config " + sig(rc[i]);
        s.points = true;
        s.x.push_back(rx[i]);
        s.y.push_back(rr[i]);
      }
      LinePlot p;
      p.name = "residuals";
      p.title = "Residuals of the separation";
      p.xlabel = "x / mm";
      p.ylabel = "residual / \xC2\xB5m";
      for (auto& [c, s] : by_config)
        p.series.push_back(std::move(s));
      plot_line(p, "Residuals per sensor configuration");
      double sq = 0;
      for (double v : rr)
        sq += v * v;
      html.configuration.emplace_back("residual rms (um)",
                                      sig(std::sqrt(sq / static_cast<double>(rr.size()))));
    }
    // A least-squares result (λ = 0: a scan sequence's fit, --rule ls) has no λ search to draw:
    // its lcurve.csv has no rows.
    const bool no_lambda_search = fs::exists(dir / "lcurve.csv") && [&] {
      const auto t = read_csv(dir / "lcurve.csv", {.allow_non_finite = false, .min_rows = 0});
      return t.rows.empty() && t.meta("lambda_rule") == std::optional<std::string>("least_squares");
    }();
    if (fs::exists(dir / "lcurve.csv") && !no_lambda_search) {
      const auto t = read_csv(dir / "lcurve.csv", {.allow_non_finite = false, .min_rows = 2});
      const auto lam = t.column("lambda", dir / "lcurve.csv");
      // The L-curve (rule lcurve), or the criterion a likelihood rule minimised over λ.
      const std::string rule = t.meta("lambda_rule").value_or("?");
      const bool curve = t.find_column("residual_norm").has_value();
      const auto rn = curve ? t.column("residual_norm", dir / "lcurve.csv") : lam;
      const auto sn = curve ? t.column("solution_norm", dir / "lcurve.csv")
                            : t.column(rule + "_criterion", dir / "lcurve.csv");
      LinePlot p;
      p.name = "lcurve";
      p.title = curve ? "L-curve" : "lambda search: " + rule + " criterion";
      p.xlabel = curve ? "residual norm ||A x - b||" : "lambda";
      p.ylabel = curve ? "solution norm ||x||" : rule + " criterion (smaller is better)";
      p.log_x = true;
      p.log_y = curve;
      p.series.push_back({curve ? "L-curve" : rule, rn, sn, {}});
      if (auto lc = t.meta("lambda_chosen")) {
        double chosen = 0;
        try {
          chosen = std::stod(*lc);
        } catch (const std::exception&) {
          throw CsvError(dir / "lcurve.csv", 0, "lambda_chosen '" + *lc + "' is not a number");
        }
        std::size_t best = 0;
        for (std::size_t i = 1; i < lam.size(); ++i)
          if (std::abs(std::log(lam[i] / chosen)) < std::abs(std::log(lam[best] / chosen)))
            best = i;
        p.marker = {rn[best], sn[best]};
        p.marker_label =
            "lambda = " + sig(chosen, 3) + " (" + t.meta("lambda_rule").value_or("?") + ")";
        const auto [mn, mx] = std::minmax_element(lam.begin(), lam.end());
        if (best == static_cast<std::size_t>(mn - lam.begin()) ||
            best == static_cast<std::size_t>(mx - lam.begin()))
          res.warnings.push_back("the chosen lambda " + sig(chosen, 3) +
                                 " is at the edge of the swept range: widen the range.");
        html.configuration.emplace_back("lambda chosen", *lc);
        html.configuration.emplace_back("lambda rule", t.meta("lambda_rule").value_or("?"));
      }
      plot_line(p, "L-curve (log-log) with the chosen corner");
    }

    // Compensation tables, in machine coordinates.
    if (opts.tables) {
      core::MachineAxes axes;
      std::optional<core::MachineAxes> recorded;
      try {
        recorded = machine_axes_from_metadata(md.table.metadata);
      } catch (const std::invalid_argument& e) {
        throw CsvError(motion_file, 0, e.what());
      }
      if (recorded) {
        axes = *recorded;
      } else if (opts.axes) {
        axes = *opts.axes;
      } else {
        axes.slide_start_mm = 0;
        res.warnings.push_back(
            "motion.csv does not record where the scan ran (slide_start_mm, scan_direction, "
            "reading_sign): the compensation tables are in scan coordinates from 0 mm with "
            "reading_sign +1; give the machine config (errsep-report --config) or rescan with "
            "errsep-scan.");
      }
      axes.input_axis = axis;
      axes.output_axis = dirn;
      const auto profile = core::compensation_profile(md.x, md.s, md.u_s, axes, opts.compensation);
      CompensationExportOptions eo = opts.tables_export;
      eo.coverage_factor = k;
      eo.title = es + " from " + html.raw_data_file;
      const CompensationExport ex = export_compensation(profile, eo);
      res.compensation_summary = ex.summary();
      for (const auto& t : ex.tables) {
        for (const auto& file : t.files) {
          // The table's own CSV (format csv) gets the run id too; the controllers' formats are
          // written as their controllers read them.
          outputs.emplace_back(comp_dir / file.name,
                               fs::path(file.name).extension() == ".csv"
                                   ? format_csv(with_run_id(parse_csv(file.content, file.name)), 12)
                                   : file.content);
          html.files.emplace_back("compensation/" + file.name,
                                  compensation_writer(t.format).description() + "; " +
                                      std::to_string(t.read_back.table.points()) +
                                      " points; max interpolation error " +
                                      sig(t.accuracy.max_um, 3) + " um");
        }
      }
      outputs.emplace_back(comp_dir / "accuracy.csv",
                           format_csv(with_run_id(ex.accuracy_csv()), 10));
      html.files.emplace_back("compensation/accuracy.csv",
                              "each table's interpolation error against the measurement, with U");
      html.notes.push_back(
          "Compensation sign: comp(p) = -error(p) at machine positions p of " +
          std::string(1, axis) + " (from " + sig(profile.first_mm(), 6) + " to " +
          sig(profile.last_mm(), 6) + " mm; reading_sign " + (axes.reading_sign > 0 ? "+1" : "-1") +
          "), added to the " + std::string(1, dirn) +
          " command (actual = commanded + comp + error = commanded). The " +
          (opts.compensation.remove_line ? std::string(core::label(*opts.compensation.remove_line))
                                         : std::string("no line")) +
          " was removed from the error first (the alignment of the artefact is not a machine "
          "error).");
      {
        std::istringstream lines(ex.summary());
        for (std::string l; std::getline(lines, l);)
          html.notes.push_back("Table " + l);
      }
      {
        LinePlot p;
        p.name = "compensation";
        p.title = es + " compensation";
        p.xlabel = std::string(1, axis) + " machine position / mm";
        p.ylabel = "\xC2\xB5m";
        p.series.push_back({"-error (line removed)", profile.position_mm, profile.comp_um,
                            profile.u_um.empty() ? profile.u_um : scaled(profile.u_um, k)});
        for (const auto& t : ex.tables) {
          if (t.format == CompensationFormat::csv) continue;
          p.series.push_back({std::string(to_string(t.format)) + " (" +
                                  std::to_string(t.read_back.table.points()) + " points)",
                              t.read_back.table.position_mm,
                              t.read_back.table.comp_um,
                              {}});
        }
        plot_line(p,
                  "Compensation: the measured -error with its expanded uncertainty and each "
                  "controller's table as read back");
      }
    }
  }

  // ---- displacement-method grid ------------------------------------------------------------
  if (auto g = find_grid(dir, opts.grid_csv)) {
    res.grid = true;
    if (!res.four_sensor) {
      for (const auto& [key, v] : g->table.metadata)
        html.configuration.emplace_back(key, v);
      if (auto src = g->table.meta("source")) html.raw_data_file = *src;
      html.title = "errsep scan report: flatness of w(x, y)";
    }
    html.configuration.emplace_back("grid file", g->file.filename().string());
    std::vector<double> u = g->u_w;
    if (u.empty() && opts.u_w_um > 0) u.assign(g->w.size(), opts.u_w_um);
    if (u.empty() || all_zero(u))
      res.warnings.push_back(
          "no uncertainty for w(x, y) (column u_w_um or --u-w-um): flatness "
          "uncertainties are not available.");
    for (const auto ref : {ReferencePlane::least_squares, ReferencePlane::minimum_zone}) {
      const auto r = core::evaluate_flatness(g->x, g->y, g->w, u, ref, opts.evaluation);
      if (!r.converged)
        res.warnings.push_back(
            "minimum-zone flatness: pivot limit reached; value is an upper bound.");
      add_eval({"-", "flatness of w(x, y)", core::label(ref),
                std::string("flatness_") + core::to_string(ref), "um", r.flatness_um,
                r.uncertainty.expanded});
    }
    HeatMap hm;
    hm.name = "surface_w";
    hm.title = "Surface profile w(x, y)";
    hm.xlabel = "x / mm";
    hm.ylabel = "y / mm";
    hm.cblabel = "w / \xC2\xB5m";
    hm.x = g->x;
    hm.y = g->y;
    hm.z = g->w;
    plot_map(hm, "Heat map of the separated surface w(x, y) (cf. Haramiishi et al. 2024, Fig. 13)");
    // Motion errors of the two tables (Haramiishi 2024 Eq. 27): m2x along x (Fig. 18) and m4y
    // along y (Fig. 19), both in the sensing direction z: ISO 230-1 EZX and EZY.
    for (const auto& [col, sym, fig] :
         {std::tuple{"m2x_um", "EZX", "Fig. 18"}, std::tuple{"m4y_um", "EZY", "Fig. 19"}}) {
      if (!g->table.find_column(col)) continue;
      const auto v = g->table.column(col, g->file);
      const auto [mn, mx] = std::minmax_element(v.begin(), v.end());
      const std::string name = std::string(col).substr(0, std::string(col).size() - 3);
      add_eval({sym, "motion error " + name + "(x, y) (peak to valley)", "max - min",
                std::string(sym) + "_pv", "um", *mx - *mn, 0});
      HeatMap mm = hm;
      mm.name = "motion_" + name;
      mm.title = std::string(sym) + ": motion error " + name + "(x, y)";
      mm.cblabel = name + " / \xC2\xB5m";
      mm.z = v;
      plot_map(mm, std::string(sym) + ": heat map of the motion error " + name +
                       " (cf. Haramiishi et al. 2024, " + fig + ")");
    }
    if (!g->m.empty()) {
      const auto [mn, mx] = std::minmax_element(g->m.begin(), g->m.end());
      add_eval({"-", "motion error " + g->m_column + " (peak to valley)", "max - min",
                "motion_error_pv", "um", *mx - *mn, 0});
      HeatMap mm = hm;
      mm.name = "motion_error";
      mm.title = "Motion error " + g->m_column.substr(0, g->m_column.size() - 3) + "(x, y)";
      mm.cblabel = "m / \xC2\xB5m";
      mm.z = g->m;
      plot_map(mm, "Heat map of the motion error (cf. Haramiishi et al. 2024, Figs. 18-19)");
    }
  }

  // ---- one-axis displacement result ----------------------------------------------------------
  if (!res.four_sensor && !res.grid) {
    if (auto d = find_one_axis(dir)) {
      res.grid = true;
      for (const auto& [key, v] : d->table.metadata)
        html.configuration.emplace_back(key, v);
      if (auto src = d->table.meta("source")) html.raw_data_file = *src;
      html.configuration.emplace_back("profile file", d->file.filename().string());
      const char axis = upper_axis(
          opts.axis ? opts.axis : d->table.meta("axis").value_or("X").c_str()[0], "axis");
      const char dirn = upper_axis(
          opts.direction ? opts.direction
                         : d->table.meta("straightness_direction").value_or("Z").c_str()[0],
          "straightness direction");
      const std::string es = core::straightness_symbol(axis, dirn);
      html.title = "errsep scan report: " + es + " (displacement method, one axis)";
      std::vector<double> uw = d->u_w;
      if (uw.empty() && opts.u_w_um > 0) uw.assign(d->w.size(), opts.u_w_um);
      if (d->u_m.empty() && uw.empty())
        res.warnings.push_back(
            "no uncertainty columns (u_m_um, u_w_um) or --u-w: "
            "uncertainties are not available.");
      for (const auto ref :
           {ReferenceLine::end_points, ReferenceLine::least_squares, ReferenceLine::minimum_zone}) {
        const auto r = core::evaluate_straightness(d->x, d->m, d->u_m, ref, opts.evaluation);
        add_eval({es, "table motion error m(x)", core::label(ref), es + "_" + core::to_string(ref),
                  "um", r.straightness_um, r.uncertainty.expanded});
      }
      for (const auto ref : {ReferenceLine::least_squares, ReferenceLine::minimum_zone}) {
        const auto r = core::evaluate_straightness(d->x, d->w, uw, ref, opts.evaluation);
        add_eval({"-", "workpiece profile w(x)", core::label(ref),
                  std::string("w_") + core::to_string(ref), "um", r.straightness_um,
                  r.uncertainty.expanded});
      }
      LinePlot p;
      p.name = "displacement_profiles";
      p.title = "Displacement method: w(x) and m(x)";
      p.xlabel = "x / mm";
      p.ylabel = "\xC2\xB5m";
      p.series.push_back({"w(x) workpiece", d->x, d->w, uw.empty() ? uw : scaled(uw, k)});
      p.series.push_back({"m(x) motion error (" + es + ")", d->x, d->m,
                          d->u_m.empty() ? d->u_m : scaled(d->u_m, k)});
      plot_line(p,
                "Workpiece profile w(x) and table motion error m(x) (cf. Haramiishi et al. "
                "2024, Figs. 8-9)");
      // The loop's account (service::DisplacementPipeline with refine on, issue 16 item 4).
      if (const fs::path rel = find_refine_file(dir, "displacement_refine.csv"); !rel.empty()) {
        const fs::path rf = dir / rel;
        // No rows when nothing was taken and the plan leaves nothing unidentifiable (scan 2
        // backwards on clean data): the table says so.
        const auto t = read_csv(rf, {.allow_non_finite = true, .min_rows = 0});
        HtmlTable rt = displacement_refine_table(t, rf);
        rt.caption = rel.string() + ": " + rt.caption;
        html.tables.push_back(std::move(rt));
        html.files.emplace_back(linked_from_report(opts, rel),
                                "the displacement loop's account; the refined w, m with their u "
                                "in " +
                                    (rel.parent_path() / "displacement.csv").string());
      }
    }
  }

  if (!res.four_sensor && !res.grid) {
    // Say what was looked for, and what to do with what is there.
    std::string hint;
    if (fs::exists(dir / "raw.csv"))
      hint +=
          "; it holds a raw four-sensor scan (raw.csv) but no separation: run errsep-separate " +
          (dir / "raw.csv").string() + " --out DIR (or errsep-scan without --no-separate)";
    if (fs::exists(dir / "raw_displacement.csv"))
      hint +=
          "; it holds a raw displacement scan (raw_displacement.csv) but no separation "
          "(displacement.csv): run errsep-separate-displacement one-axis -i " +
          (dir / "raw_displacement.csv").string() + " -o " + (dir / "displacement.csv").string() +
          " (or errsep-scan without --no-separate)";
    throw std::runtime_error(
        dir.string() +
        ": no result errsep-report can read: no motion.csv (four-sensor result of errsep-scan, "
        "errsep-separate, errsep-refine, errsep-simulate), no grid CSV (x_mm, y_mm, w_um: "
        "two-axis displacement result) and no one-axis profile (x_mm, m_um, w_um: displacement "
        "result)" +
        hint);
  }

  // ---- tables, text, html --------------------------------------------------------------------
  HtmlTable ev;
  ev.id = "evaluation";
  ev.caption = "ISO 230-1 evaluation (U: expanded uncertainty, k = " + sig(k) + ", correlation " +
               core::to_string(opts.evaluation.correlation) + ")";
  ev.header = {"ISO 230-1", "quantity", "reference", "value \xC2\xB1 U", "unit"};
  for (const auto& r : rows)
    ev.rows.push_back({r.symbol, r.quantity, r.reference,
                       format_value_with_uncertainty(r.value, r.expanded),
                       r.unit == "um"     ? "\xC2\xB5m"
                       : r.unit == "urad" ? "\xC2\xB5rad"
                                          : r.unit});
  html.tables.push_back(ev);
  if (fs::exists(dir / "verification.csv")) {
    const fs::path vf = dir / "verification.csv";
    const auto vt = read_csv(vf, {.allow_non_finite = false, .min_rows = 1});
    HtmlTable v;
    v.id = "verification";
    v.caption = "Measure - compensate - verify (minimum-zone straightness, U with k = " +
                vt.meta("coverage_factor").value_or("?") + ")";
    v.header = {"", "value"};
    for (const auto& [q, val] : verification_rows(vt, vf))
      v.rows.push_back({q, val});
    html.tables.push_back(v);
    html.files.emplace_back("verification.csv",
                            "before, predicted and measured residual at machine positions");
  }
  // io::refine_csv's and io::sequence_refine_csv's u_S_unbounded<i>: a term of the refined u_S
  // held at the readings' bound.
  auto warn_unbounded = [&](const CsvTable& t, const std::string& whose) {
    for (int i = 0; t.meta("u_S_unbounded" + std::to_string(i)); ++i)
      res.warnings.push_back(whose +
                             "refined u_S is not bounded by the data (held at the readings' "
                             "bound, not a measured uncertainty): " +
                             *t.meta("u_S_unbounded" + std::to_string(i)));
  };
  // The refine step (find_refine_file).  The base step has no parameters: nan there.
  if (const fs::path rel = find_refine_file(dir, "refine_steps.csv"); !rel.empty()) {
    const fs::path rf = dir / rel;
    const auto t = read_csv(rf, {.allow_non_finite = true, .min_rows = 1});
    HtmlTable rt = refine_steps_table(t, rf);
    rt.caption = rel.string() + ": " + rt.caption;
    html.tables.push_back(std::move(rt));
    html.files.emplace_back(
        linked_from_report(opts, rel),
        "the refine step table; the refined S, gamma, f are in " +
            (rel.has_parent_path() ? std::string("refine/motion.csv, refine/reference.csv")
                                   : std::string("motion.csv, reference.csv of this folder")));
    // service/refine_run.cpp's refine_role: a scan sequence's result is its own refined fit
    // (sequence_refine.csv), and this table the single-scan refine kept for comparison, whose
    // findings do not concern the result's figures.
    const bool comparison = refine_role_of(t, rf) == RefineRole::comparison;
    const std::string whose =
        comparison ? ": the single-scan refine kept for comparison (the result is the scan "
                     "sequence's fit, which this does not concern): its "
                   : ": the ";
    if (auto m = t.meta("model_complete"); m && *m != "true")
      res.warnings.push_back(rf.string() + whose +
                             "refined model is incomplete (residual not white or implausible "
                             "effects rejected): see refine_report.txt beside it.");
    warn_unbounded(t, rf.string() + whose);
  }
  // A scan sequence's findings (service::FourSensorPipeline with refine on): what drift or
  // non-repeat the redundant traverses show, and what the plan could not identify.
  if (const fs::path rel = find_refine_file(dir, "sequence_refine.csv"); !rel.empty()) {
    const fs::path sf = dir / rel;
    const auto t = read_csv(sf, {.allow_non_finite = true, .min_rows = 1});
    html.tables.push_back(sequence_findings_table(t, sf));
    warn_unbounded(t, sf.string() + ": the scan sequence fit's ");
    html.files.emplace_back(
        linked_from_report(opts, rel),
        "the scan sequence's fit: S and u_S before and after its refine, and its findings");
  }
  // The particulars a customer's report states; what the inputs do not say is said to be unknown.
  const ReportParticulars& pt = opts.particulars;
  auto stated = [](const std::string& v, const char* none) { return v.empty() ? none : v; };
  html.measurement = {
      {"Date and time of the measurement (UTC)",
       raw_value("started_utc")
               .value_or(
                   "not recorded (no raw.csv or raw_displacement.csv with '# started_utc:')") +
           (raw_value("finished_utc") ? " to " + *raw_value("finished_utc") : "")},
      {"Machine", stated(pt.machine, "not stated")},
      {"Axis", axis_line},
      {"Operator", stated(pt.operator_name, "not stated")},
      {"Instrument and sensor",
       stated(pt.instrument, "not stated") +
           (raw_value("sensors") ? "; sensors: " + *raw_value("sensors") +
                                       (raw_value("setup") ? " (" + *raw_value("setup") + ")" : "")
                                 : "")},
      {"Environment temperature", pt.temperature_c ? sig(*pt.temperature_c, 4) + " \xC2\xB0"
                                                                                 "C"
                                                   : "not recorded"},
      {"Software", std::string("errsep ") + kVersion},
      {"Standard applied",
       "ISO 230-1:2012 (straightness and angular deviation of a linear axis: end-point, "
       "least-squares and minimum-zone reference lines); uncertainty after the GUM (JCGM "
       "100:2008), U = k u_c with k = " +
           sig(k) + "; separation after Zhao et al. 2019 (four-sensor method)"},
      {"Tolerance", pt.straightness_tolerance_um
                        ? sig(*pt.straightness_tolerance_um) +
                              " \xC2\xB5m on the straightness (minimum zone); decision rule ISO "
                              "14253-1 (U counts against conformance)"
                        : "none configured: no verdict"}};
  if (res.grid && !res.four_sensor)
    html.measurement[7].second =
        "ISO 230-1:2012 (straightness, flatness); uncertainty after the GUM (JCGM 100:2008); "
        "separation after Haramiishi et al. 2024 (extended displacement method)";
  if (pt.straightness_tolerance_um) {
    if (mz_straightness)
      res.verdict = conformance_verdict(mz_straightness->first, mz_straightness->second,
                                        *pt.straightness_tolerance_um);
    else
      res.warnings.push_back(
          "a straightness tolerance is configured, but this result has no straightness of S: no "
          "verdict.");
    html.verdict = res.verdict;
  }
  html.notes.insert(html.notes.begin(), res.warnings.begin(), res.warnings.end());
  html.notes.push_back(
      std::string("Uncertainty: each figure is linear in the profile at the solution (active "
                  "points fixed); U = k u_c with ") +
      (opts.evaluation.correlation == core::Correlation::bound
           ? "u_c = sum |c_i| u_i, an upper bound valid for any correlation between points"
           : "u_c = sqrt(sum c_i^2 u_i^2), points taken as uncorrelated") +
      ". Minimum zone: exact (hull-edge slopes for lines, simplex on the Chebyshev dual for "
      "planes).");
  for (const auto& [is_map, i] : figure_order) {
    const PlotFiles f = is_map ? render_heat_map(map_jobs[i].first, plot_dir, opts.plot)
                               : render_line_plot(line_jobs[i].first, plot_dir, opts.plot);
    for (const auto& q : {f.png, f.svg, f.script, f.data})
      if (!q.empty()) res.written.push_back(q);
    // The separation's diagnostics go to the report's appendix.
    const bool diagnostic =
        !is_map && (line_jobs[i].first.name == "residuals" || line_jobs[i].first.name == "lcurve");
    figures.push_back({is_map ? map_jobs[i].second : line_jobs[i].second,
                       opts.plot.png ? f.png : f.svg, diagnostic});
  }
  html.figures = figures;
  html.files.insert(html.files.begin(), {"evaluation.csv", "the evaluation, one row"});
  html.files.insert(html.files.begin() + 1, {"evaluation.txt", "the evaluation as text"});

  res.text = text_table(rows, k);
  if (!opts.trend_results_dir.empty()) {
    const StraightnessTrend trend = straightness_trend(opts.trend_results_dir);
    res.text += "\n" + format_trend(trend);
    outputs.emplace_back(out / "trend.csv", format_csv(with_run_id(trend_table(trend)), 10));
    html.files.push_back({"trend.csv", "straightness over the machine's past scans"});
    if (trend.any_significant())
      res.warnings.push_back("straightness changed beyond the combined U (see trend.csv)");
  }
  if (!res.verdict.empty()) res.text += "verdict: " + res.verdict + "\n";
  outputs.emplace_back(out / "evaluation.csv", format_csv(eval_csv, 12, NonFiniteCell::empty));
  outputs.emplace_back(out / "evaluation.txt", res.text);
  outputs.emplace_back(out / "report.html", render_html_report(html));
  for (const auto& [path, content] : outputs) {
    fs::create_directories(path.parent_path());
    write_file_atomic(path, content);
    res.written.push_back(path);
  }
  if (opts.pdf_printer) {
    // Printed in the staging folder, so that the PDF joins the set with the rest.
    const PdfOutcome pdf = opts.pdf_printer(out / "report.html", out / "report.pdf");
    if (pdf.written) {
      res.written.push_back(out / "report.pdf");
      res.pdf = dir / (out / "report.pdf").lexically_relative(stage.dir());
    } else {
      res.pdf_skipped = pdf.why_not;
    }
  }
  stage.commit();
  for (auto& p : res.written)  // where they are now
    p = dir / p.lexically_relative(stage.dir());
  res.html = dir / (out / "report.html").lexically_relative(stage.dir());
  return res;
}

}  // namespace errsep::io

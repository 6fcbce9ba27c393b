#include "errsep/io/straightness_trend.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "errsep/io/results_store.hpp"
#include "errsep/io/scan_report.hpp"

namespace errsep::io {
namespace {

double meta_number(const CsvTable& t, const char* key) {
  const auto v = t.meta(key);
  if (!v) return std::numeric_limits<double>::quiet_NaN();
  try {
    std::size_t used = 0;
    const double d = std::stod(*v, &used);
    return used == v->size() ? d : std::numeric_limits<double>::quiet_NaN();
  } catch (const std::exception&) {
    return std::numeric_limits<double>::quiet_NaN();
  }
}

}  // namespace

bool StraightnessTrend::any_significant() const {
  for (const auto& p : points)
    if (p.significant) return true;
  return !points.empty() && points.back().drift_significant;
}

StraightnessTrend straightness_trend(const std::filesystem::path& results_dir) {
  if (!std::filesystem::is_directory(results_dir))
    throw std::runtime_error("trend: '" + results_dir.string() +
                             "' is not a directory (the daemon's results store)");
  StraightnessTrend t;
  std::vector<StoredFile> results;
  for (const auto& e : std::filesystem::directory_iterator(results_dir))
    if (const auto f = parse_store_name(e.path()); f && f->kind == "result") results.push_back(*f);
  std::sort(results.begin(), results.end(),
            [](const auto& a, const auto& b) { return a.scan_id < b.scan_id; });
  for (const auto& f : results) {
    CsvReadOptions ro;
    ro.min_rows = 0;
    CsvTable c;
    try {
      c = read_csv(f.path, ro);
    } catch (const std::exception& e) {
      t.skipped.push_back(f.path.filename().string() + ": " + e.what());
      continue;
    }
    TrendPoint p;
    p.scan_id = f.stem;
    p.scan_number = f.scan_id;
    p.started_utc = c.meta("started_utc").value_or("");
    p.straightness_um = meta_number(c, "straightness_minimum_zone_um");
    p.U_um = meta_number(c, "straightness_minimum_zone_U_um");
    p.sigma_hat_um = meta_number(c, "sigma_hat_um");
    if (!std::isfinite(p.straightness_um) || !std::isfinite(p.U_um) || p.U_um < 0) {
      t.skipped.push_back(f.path.filename().string() +
                          ": no straightness_minimum_zone_um / _U_um in its metadata");
      continue;
    }
    if (!t.points.empty()) {
      const TrendPoint& prev = t.points.back();
      const TrendPoint& first = t.points.front();
      p.change_um = p.straightness_um - prev.straightness_um;
      p.change_U_um = std::hypot(p.U_um, prev.U_um);
      p.significant = std::abs(p.change_um) > p.change_U_um;
      p.drift_um = p.straightness_um - first.straightness_um;
      p.drift_U_um = std::hypot(p.U_um, first.U_um);
      p.drift_significant = std::abs(p.drift_um) > p.drift_U_um;
    }
    t.points.push_back(p);
  }
  return t;
}

CsvTable trend_table(const StraightnessTrend& t) {
  CsvTable c;
  c.set_meta("format", "errsep straightness trend");
  c.set_meta("rule",
             "significant: |change| > U_c = sqrt(U_a^2 + U_b^2) (k = 2, scans independent); "
             "change against the previous scan, drift against the first");
  std::string ids;
  for (const auto& p : t.points)
    ids += (ids.empty() ? "" : " ") + p.scan_id;
  c.set_meta("scan_ids", ids);
  auto col = [&](auto get) {
    std::vector<double> v;
    for (const auto& p : t.points)
      v.push_back(get(p));
    return v;
  };
  c.add_column("scan_number", col([](const TrendPoint& p) { return double(p.scan_number); }));
  c.add_column("straightness_um", col([](const TrendPoint& p) { return p.straightness_um; }));
  c.add_column("U_um", col([](const TrendPoint& p) { return p.U_um; }));
  // Only when every result says it: a CSV cell is a number (csv.hpp), never a NaN.
  bool all_sigma = true;
  for (const auto& p : t.points)
    all_sigma = all_sigma && std::isfinite(p.sigma_hat_um);
  if (all_sigma)
    c.add_column("sigma_hat_um", col([](const TrendPoint& p) { return p.sigma_hat_um; }));
  else
    c.set_meta("sigma_hat_um", "not in every result file: column left out");
  c.add_column("change_um", col([](const TrendPoint& p) { return p.change_um; }));
  c.add_column("change_U_um", col([](const TrendPoint& p) { return p.change_U_um; }));
  c.add_column("significant", col([](const TrendPoint& p) { return p.significant ? 1.0 : 0.0; }));
  c.add_column("drift_um", col([](const TrendPoint& p) { return p.drift_um; }));
  c.add_column("drift_U_um", col([](const TrendPoint& p) { return p.drift_U_um; }));
  c.add_column("drift_significant",
               col([](const TrendPoint& p) { return p.drift_significant ? 1.0 : 0.0; }));
  return c;
}

std::string format_trend(const StraightnessTrend& t) {
  std::ostringstream os;
  os << "Straightness trend (minimum zone, U with k = 2) over " << t.points.size()
     << " scans of the results store\n";
  for (const auto& p : t.points) {
    os << "  " << p.scan_id << "  " << format_value_with_uncertainty(p.straightness_um, p.U_um)
       << " um";
    if (&p != &t.points.front()) {
      os << "  change " << format_value_with_uncertainty(p.change_um, p.change_U_um)
         << (p.significant ? "  SIGNIFICANT" : "") << "  since first "
         << format_value_with_uncertainty(p.drift_um, p.drift_U_um)
         << (p.drift_significant ? "  SIGNIFICANT" : "");
    }
    os << "\n";
  }
  for (const auto& s : t.skipped)
    os << "  skipped: " << s << "\n";
  os << (t.any_significant()
             ? "A change beyond the combined U: the slideway's straightness has changed.\n"
             : "No change beyond the combined U.\n");
  return os.str();
}

}  // namespace errsep::io

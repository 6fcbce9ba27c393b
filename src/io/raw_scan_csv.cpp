#include "errsep/io/raw_scan_csv.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "errsep/io/plausibility.hpp"
#include "errsep/io/staged_directory.hpp"

namespace errsep::io {
namespace {

std::optional<std::string> find_meta(const std::vector<std::pair<std::string, std::string>>& md,
                                     const std::string& key) {
  for (const auto& [k, v] : md)
    if (k == key) return v;
  return std::nullopt;
}

std::string fmt(double v) {
  std::ostringstream os;
  os.precision(12);
  os << v;
  return os.str();
}

void check_len(const std::vector<double>& v, std::size_t n, const std::string& col) {
  if (v.size() != n)
    throw std::invalid_argument("raw scan: column '" + col + "' has " + std::to_string(v.size()) +
                                " values for " + std::to_string(n) + " positions");
}

/// Reading times go the way the rows were read: forward, they do not decrease from row to row;
/// backward (the last row read first), they do not increase.  `declared` names what said
/// backward, for the message (e.g. "scan2_order is backward").
void check_time_order(const CsvTable& t, const std::string& column, bool backward,
                      const std::filesystem::path& file, bool allow_nan,
                      const std::string& declared) {
  if (!backward) {
    check_increasing(t, column, false, file, allow_nan);
    return;
  }
  const std::size_t c = *t.find_column(column);
  double next = 0;
  bool have_next = false;
  for (std::size_t r = t.rows.size(); r-- > 0;) {
    const double v = t.rows[r][c];
    if (std::isnan(v) && allow_nan) continue;
    const std::size_t line = r < t.row_line.size() ? t.row_line[r] : 0;
    if (!std::isfinite(v))
      throw CsvError(file, line, "column '" + column + "': " + fmt(v) + " is not finite");
    if (have_next && v < next)
      throw CsvError(file, line,
                     "column '" + column + "': " + fmt(v) + " before " + fmt(next) +
                         " on the row below, but " + declared +
                         " (the rows are read bottom up): time goes backwards");
    have_next = true;
    next = v;
  }
}

/// Completeness rule of both formats (see the header).
bool read_complete(const CsvTable& t, const std::filesystem::path& file) {
  const auto c = t.meta("complete");
  if (c && *c != "true" && *c != "false")
    throw CsvError(file, t.meta_line("complete"),
                   "metadata 'complete: " + *c + "': must be true or false");
  if (t.meta("format")) return c && *c == "true";
  return !(c && *c == "false");
}

void require_complete(bool complete, const CsvTable& t, const std::filesystem::path& file,
                      const RawReadOptions& opts) {
  if (!complete && opts.require_complete) {
    std::string why = t.meta("stop_reason").value_or("no reason recorded");
    throw CsvError(file, t.meta_line("complete"),
                   "scan is marked incomplete (complete: false; stop_reason: " + why +
                       "): it is kept as a record but cannot be separated");
  }
}

std::vector<std::pair<std::string, std::string>> other_meta(
    const CsvTable& t, std::initializer_list<const char*> known) {
  std::vector<std::pair<std::string, std::string>> out;
  for (const auto& kv : t.metadata) {
    bool skip = false;
    for (const char* k : known)
      skip = skip || kv.first == k;
    if (!skip) out.push_back(kv);
  }
  return out;
}

int parse_int_meta(const CsvTable& t, const std::string& key, const std::filesystem::path& file) {
  const std::string v = *t.meta(key);
  int out = 0;
  const auto [p, ec] = std::from_chars(v.data(), v.data() + v.size(), out);
  if (ec != std::errc() || p != v.data() + v.size())
    throw CsvError(file, t.meta_line(key), "metadata '" + key + ": " + v + "': not an integer");
  return out;
}

// The sequence of the header's file comment: "traverses: T", one "traverse_K: configuration c,
// forward|backward, start_s t[, zero_shift_um Δ]" line and the columns kK_um, kK_t_s for each
// (zero_shift_um: the traverse read with the sensor re-zeroed by Δ, the rezeroed plan of
// core/scan_sequence.hpp; written only when non-zero, absent = 0).
RawSequence read_sequence(const CsvTable& t, const std::filesystem::path& file, bool complete) {
  RawSequence q;
  q.plan = t.meta("plan").value_or("custom");
  const int T = parse_int_meta(t, "traverses", file);
  // Every error here names the metadata line it concerns (a missing traverse: the line that
  // announced T of them).
  const std::size_t t_line = t.meta_line("traverses");
  if (T < 4 || T > 64)
    throw CsvError(file, t_line, "metadata 'traverses: " + std::to_string(T) + "': must be 4..64");
  for (int k = 1; k <= T; ++k) {
    const std::string key = "traverse_" + std::to_string(k);
    const auto v = t.meta(key);
    if (!v)
      throw CsvError(file, t_line,
                     "metadata '" + key + "' missing (traverses: " + std::to_string(T) + ")");
    const std::size_t line = t.meta_line(key);
    core::Traverse tr;
    char dir[16] = {0};
    int c = 0;
    double start = 0;
    int used = 0;
    if (std::sscanf(v->c_str(), "configuration %d, %15[a-z], start_s %lf%n", &c, dir, &start,
                    &used) != 3 ||
        c < 1 || c > 4 || !core::traverse_direction_from_string(dir, &tr.direction))
      throw CsvError(file, line,
                     "metadata '" + key + ": " + *v + "': expected 'configuration 1..4, " +
                         to_string(core::TraverseDirection::forward) + "|" +
                         to_string(core::TraverseDirection::backward) +
                         ", start_s <s>[, zero_shift_um <um>]'");
    // A re-zeroed traverse (the rezeroed plan) states its zero shift; absent = 0.
    const std::string rest = v->substr(static_cast<std::size_t>(used));
    if (!rest.empty()) {
      int used2 = 0;
      if (std::sscanf(rest.c_str(), ", zero_shift_um %lf%n", &tr.zero_shift_um, &used2) != 1 ||
          static_cast<std::size_t>(used2) != rest.size() || !std::isfinite(tr.zero_shift_um))
        throw CsvError(file, line,
                       "metadata '" + key + ": " + *v +
                           "': after start_s expected nothing or "
                           "', zero_shift_um <um>' (a finite number), got '" +
                           rest + "'");
    }
    tr.configuration = c - 1;
    tr.start_s = start;
    q.traverses.push_back(tr);
    const std::string m = "k" + std::to_string(k), mc = m + "_um", tc = m + "_t_s";
    // The sensor of configuration c reads it: its recorded range applies.
    check_readings(t, mc, reading_range(t, "m" + std::to_string(c), file), file, !complete);
    // Each traverse's times go the way it moved the slide (a backward one reads the last row
    // first).
    check_time_order(t, tc, tr.direction == core::TraverseDirection::backward, file, !complete,
                     key + " is backward");
    q.m_um.push_back(t.column(mc, file));
    q.t_s.push_back(t.column(tc, file));
  }
  core::ScanSequence seq;
  seq.traverses = q.traverses;
  if (std::string why; !seq.is_valid(&why))
    throw CsvError(file, t_line, "scan sequence (traverse_1.." + std::to_string(T) + "): " + why);
  return q;
}

}  // namespace

std::optional<std::string> RawFourSensorScan::meta(const std::string& key) const {
  return find_meta(metadata, key);
}
std::optional<std::string> RawDisplacementScan::meta(const std::string& key) const {
  return find_meta(metadata, key);
}

CsvTable to_csv_table(const RawFourSensorScan& scan) {
  const std::size_t n = scan.x_mm.size();
  CsvTable t;
  t.set_meta("format", kRawFourSensorFormat);
  t.set_meta("complete", scan.complete ? "true" : "false");
  t.set_meta("units", "x in mm, m in um, t in s since scan start");
  if (scan.geometry) {
    t.set_meta("dx_mm", fmt(scan.geometry->dx_mm));
    t.set_meta("s2", std::to_string(scan.geometry->s2));
    t.set_meta("s3", std::to_string(scan.geometry->s3));
    t.set_meta("s4", std::to_string(scan.geometry->s4));
    t.set_meta("N", std::to_string(scan.geometry->N));
  }
  for (const auto& [k, v] : scan.metadata)
    t.set_meta(k, v);
  t.add_column("x_mm", scan.x_mm);
  for (int i = 0; i < 4; ++i) {
    const std::string col = "m" + std::to_string(i + 1) + "_um";
    check_len(scan.m_um[static_cast<std::size_t>(i)], n, col);
    t.add_column(col, scan.m_um[static_cast<std::size_t>(i)]);
  }
  if (scan.t_s)
    for (int i = 0; i < 4; ++i) {
      const std::string col = "t" + std::to_string(i + 1) + "_s";
      check_len((*scan.t_s)[static_cast<std::size_t>(i)], n, col);
      t.add_column(col, (*scan.t_s)[static_cast<std::size_t>(i)]);
    }
  if (scan.sequence) {
    const RawSequence& q = *scan.sequence;
    const std::size_t T = q.traverses.size();
    if (q.m_um.size() != T || q.t_s.size() != T)
      throw std::invalid_argument("raw scan: the sequence has " + std::to_string(T) +
                                  " traverses but " + std::to_string(q.m_um.size()) +
                                  " reading and " + std::to_string(q.t_s.size()) + " time columns");
    t.set_meta("plan", q.plan);
    t.set_meta("traverses", std::to_string(T));
    for (std::size_t k = 0; k < T; ++k) {
      const auto& tr = q.traverses[k];
      const std::string K = std::to_string(k + 1);
      t.set_meta("traverse_" + K,
                 "configuration " + std::to_string(tr.configuration + 1) + ", " +
                     core::to_string(tr.direction) + ", start_s " + fmt(tr.start_s) +
                     (tr.zero_shift_um != 0.0 ? ", zero_shift_um " + fmt(tr.zero_shift_um) : ""));
      check_len(q.m_um[k], n, "k" + K + "_um");
      check_len(q.t_s[k], n, "k" + K + "_t_s");
      t.add_column("k" + K + "_um", q.m_um[k]);
      t.add_column("k" + K + "_t_s", q.t_s[k]);
    }
  }
  return t;
}

void set_sequence(RawFourSensorScan& scan, const core::ScanSequence& seq,
                  const Eigen::MatrixXd& m_um, const Eigen::MatrixXd& t_s) {
  const auto P = static_cast<Eigen::Index>(scan.positions());
  const auto T = static_cast<Eigen::Index>(seq.size());
  if (m_um.rows() != P || m_um.cols() != T || t_s.rows() != P || t_s.cols() != T)
    throw std::invalid_argument("set_sequence: readings and times must be P x T (" +
                                std::to_string(P) + " x " + std::to_string(T) + ")");
  RawSequence q;
  q.plan = seq.name;
  q.traverses = seq.traverses;
  auto column = [P](const Eigen::MatrixXd& M, Eigen::Index k) {
    return std::vector<double>(M.col(k).data(), M.col(k).data() + P);
  };
  scan.t_s.emplace();
  std::array<bool, 4> done{};
  for (Eigen::Index k = 0; k < T; ++k) {
    q.m_um.push_back(column(m_um, k));
    q.t_s.push_back(column(t_s, k));
    const auto c =
        static_cast<std::size_t>(seq.traverses[static_cast<std::size_t>(k)].configuration);
    if (done[c]) continue;
    done[c] = true;
    scan.m_um[c] = q.m_um.back();
    (*scan.t_s)[c] = q.t_s.back();
  }
  scan.sequence = std::move(q);
}

std::pair<core::ScanSequence, Eigen::MatrixXd> scan_sequence_of(const RawFourSensorScan& scan) {
  if (!scan.geometry)
    throw std::invalid_argument("raw scan has no geometry (dx_mm, s2, s3, s4, N)");
  const auto P = static_cast<Eigen::Index>(scan.positions());
  core::ScanSequence seq;
  Eigen::MatrixXd m;
  if (!scan.sequence) {
    seq = core::ScanSequence::make(core::ScanSequenceKind::single, *scan.geometry);
    m.resize(P, 4);
    for (int c = 0; c < 4; ++c)
      for (Eigen::Index n = 0; n < P; ++n)
        m(n, c) = scan.m_um[static_cast<std::size_t>(c)][static_cast<std::size_t>(n)];
    return {seq, m};
  }
  const RawSequence& q = *scan.sequence;
  seq.traverses = q.traverses;
  seq.name = q.plan;
  const auto T = static_cast<Eigen::Index>(q.traverses.size());
  m.resize(P, T);
  for (Eigen::Index k = 0; k < T; ++k)
    for (Eigen::Index n = 0; n < P; ++n)
      m(n, k) = q.m_um[static_cast<std::size_t>(k)][static_cast<std::size_t>(n)];
  // The slide speed of core's time model, from the first traverse's recorded times; the
  // recorded times themselves where every one is known (a complete scan).
  const auto& t0 = q.t_s.front();
  const double dt = std::abs(t0.back() - t0.front());
  if (P > 1 && dt > 0) seq.speed_mm_per_s = std::abs(scan.x_mm.back() - scan.x_mm.front()) / dt;
  Eigen::MatrixXd t(P, T);
  for (Eigen::Index k = 0; k < T; ++k)
    for (Eigen::Index n = 0; n < P; ++n)
      t(n, k) = q.t_s[static_cast<std::size_t>(k)][static_cast<std::size_t>(n)];
  if (t.allFinite()) seq.recorded_times_s = t;
  return {seq, m};
}

CsvTable to_csv_table(const RawDisplacementScan& scan) {
  const std::size_t n = scan.x_mm.size();
  CsvTable t;
  t.set_meta("format", kRawDisplacementFormat);
  t.set_meta("complete", scan.complete ? "true" : "false");
  t.set_meta("units", "x in mm, s in um, t in s since scan start");
  t.set_meta("d_mm", fmt(scan.d_mm));
  t.set_meta("scan2_order", core::to_string(scan.scan2_order));
  for (const auto& [k, v] : scan.metadata)
    t.set_meta(k, v);
  t.add_column("x_mm", scan.x_mm);
  const std::pair<const char*, const std::vector<double>*> cols[] = {
      {"s1_scan1_um", &scan.s1_scan1_um},
      {"s2_scan1_um", &scan.s2_scan1_um},
      {"s1_scan2_um", &scan.s1_scan2_um},
      {"s2_scan2_um", &scan.s2_scan2_um}};
  for (const auto& [name, v] : cols) {
    check_len(*v, n, name);
    t.add_column(name, *v);
  }
  if (scan.t_scan1_s && scan.t_scan2_s) {
    check_len(*scan.t_scan1_s, n, "t_scan1_s");
    check_len(*scan.t_scan2_s, n, "t_scan2_s");
    t.add_column("t_scan1_s", *scan.t_scan1_s);
    t.add_column("t_scan2_s", *scan.t_scan2_s);
  }
  return t;
}

void write_raw_four_sensor_csv(const std::filesystem::path& file, const RawFourSensorScan& scan) {
  write_csv(file, to_csv_table(scan), 12);
}

void write_raw_displacement_csv(const std::filesystem::path& file,
                                const RawDisplacementScan& scan) {
  write_csv(file, to_csv_table(scan), 12);
}

RawFourSensorScan read_raw_four_sensor_csv(const std::filesystem::path& file,
                                           const RawReadOptions& opts) {
  require_whole_set_of(file);  // a raw scan in a result folder: the folder must be one whole run
  CsvReadOptions ro;
  ro.allow_non_finite = true;  // nan marks cells an incomplete scan did not reach
  const CsvTable t = read_csv(file, ro);
  if (const auto f = t.meta("format"); f && *f != kRawFourSensorFormat)
    throw CsvError(
        file, t.meta_line("format"),
        "format '" + *f + "' is not a four-sensor raw scan ('" + kRawFourSensorFormat + "')");
  RawFourSensorScan s;
  s.complete = read_complete(t, file);
  require_complete(s.complete, t, file, opts);
  s.x_mm = t.column("x_mm", file);
  s.row_line = t.row_line;
  for (int i = 0; i < 4; ++i)
    s.m_um[static_cast<std::size_t>(i)] = t.column("m" + std::to_string(i + 1) + "_um", file);
  int n_t = 0;
  for (int i = 0; i < 4; ++i)
    n_t += t.find_column("t" + std::to_string(i + 1) + "_s") ? 1 : 0;
  if (n_t != 0 && n_t != 4)
    throw CsvError(file, 1, "timestamp columns t1_s..t4_s: give all four or none");
  // Plausibility before anything is computed: positions increase, each reading lies within its
  // sensor's range, the time of each configuration's readings does not go backwards (each is
  // read position by position).  NaN only where an incomplete scan did not measure.
  check_increasing(t, "x_mm", true, file, false);
  for (int i = 1; i <= 4; ++i) {
    const std::string m = "m" + std::to_string(i);
    check_readings(t, m + "_um", reading_range(t, m, file), file, !s.complete);
  }
  if (n_t == 4) {
    s.t_s.emplace();
    for (int i = 0; i < 4; ++i)
      (*s.t_s)[static_cast<std::size_t>(i)] = t.column("t" + std::to_string(i + 1) + "_s", file);
  }
  if (t.meta("dx_mm")) {
    for (const char* k : {"s2", "s3", "s4", "N"})
      if (!t.meta(k))
        throw CsvError(file, t.meta_line("dx_mm"),
                       std::string("metadata has dx_mm but not '") + k +
                           "': give the whole geometry (dx_mm, s2, s3, s4, N) or none");
    core::FourSensorConfig g;
    g.dx_mm = *t.meta_number("dx_mm", file);
    g.s2 = parse_int_meta(t, "s2", file);
    g.s3 = parse_int_meta(t, "s3", file);
    g.s4 = parse_int_meta(t, "s4", file);
    g.N = parse_int_meta(t, "N", file);
    std::string why;
    if (!g.is_valid(&why))
      throw CsvError(file, t.meta_line("dx_mm"), "geometry in metadata: " + why);
    if (s.complete && static_cast<std::size_t>(g.positions()) != s.x_mm.size())
      throw CsvError(file, t.meta_line("N"),
                     "geometry N - s2 - s3 - s4 = " + std::to_string(g.positions()) +
                         " slide positions, but the file has " + std::to_string(s.x_mm.size()) +
                         " rows");
    s.geometry = g;
  }
  if (t.meta("traverses")) s.sequence = read_sequence(t, file, s.complete);
  // m1..m4 are each configuration's first traverse: their times go the way it moved (forward
  // without a sequence; a serpentine plan reads configurations 2 and 4 backward).
  if (n_t == 4)
    for (int i = 0; i < 4; ++i) {
      bool backward = false;
      std::string declared;
      if (s.sequence)
        for (std::size_t k = 0; k < s.sequence->traverses.size(); ++k)
          if (s.sequence->traverses[k].configuration == i) {
            backward = s.sequence->traverses[k].direction == core::TraverseDirection::backward;
            declared = "traverse_" + std::to_string(k + 1) + " (configuration " +
                       std::to_string(i + 1) + "'s first) is backward";
            break;
          }
      check_time_order(t, "t" + std::to_string(i + 1) + "_s", backward, file, !s.complete,
                       declared);
    }
  s.metadata = other_meta(t, {"format", "complete", "units", "dx_mm", "s2", "s3", "s4", "N"});
  std::erase_if(s.metadata, [](const auto& kv) {
    return kv.first == "plan" || kv.first == "traverses" || kv.first.rfind("traverse_", 0) == 0;
  });
  return s;
}

RawDisplacementScan read_raw_displacement_csv(const std::filesystem::path& file,
                                              const RawReadOptions& opts) {
  require_whole_set_of(file);
  CsvReadOptions ro;
  ro.allow_non_finite = true;
  const CsvTable t = read_csv(file, ro);
  if (const auto f = t.meta("format"); f && *f != kRawDisplacementFormat)
    throw CsvError(
        file, t.meta_line("format"),
        "format '" + *f + "' is not a displacement raw scan ('" + kRawDisplacementFormat + "')");
  RawDisplacementScan s;
  s.complete = read_complete(t, file);
  require_complete(s.complete, t, file, opts);
  if (!t.meta("d_mm")) throw CsvError(file, 0, "metadata 'd_mm' (displacement d) missing");
  s.d_mm = *t.meta_number("d_mm", file);
  if (const auto o = t.meta("scan2_order")) {
    try {
      s.scan2_order = core::displacement_scan_order_from_string(*o);
    } catch (const std::invalid_argument& e) {
      throw CsvError(file, t.meta_line("scan2_order"),
                     std::string("metadata 'scan2_order': ") + e.what());
    }
  }
  s.x_mm = t.column("x_mm", file);
  s.s1_scan1_um = t.column("s1_scan1_um", file);
  s.s2_scan1_um = t.column("s2_scan1_um", file);
  s.s1_scan2_um = t.column("s1_scan2_um", file);
  s.s2_scan2_um = t.column("s2_scan2_um", file);
  const bool times = t.find_column("t_scan1_s") && t.find_column("t_scan2_s");
  // Plausibility, as for the four-sensor scan: S1 reads the workpiece in both scans, S2 the
  // reference piece; scan 1 reads the positions in order, scan 2 in its recorded order.
  check_increasing(t, "x_mm", true, file, false);
  for (const char* sensor : {"s1", "s2"})
    for (const char* scan : {"_scan1_um", "_scan2_um"})
      check_readings(t, sensor + std::string(scan), reading_range(t, sensor, file), file,
                     !s.complete);
  if (times) {
    check_increasing(t, "t_scan1_s", false, file, !s.complete);
    check_time_order(t, "t_scan2_s", s.scan2_order == core::DisplacementScanOrder::backward, file,
                     !s.complete, "scan2_order is backward");
    s.t_scan1_s = t.column("t_scan1_s", file);
    s.t_scan2_s = t.column("t_scan2_s", file);
  }
  s.metadata = other_meta(t, {"format", "complete", "units", "d_mm", "scan2_order"});
  return s;
}

}  // namespace errsep::io

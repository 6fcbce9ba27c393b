#include "errsep/io/cnc/linuxcnc_hal.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <map>
#include <regex>
#include <sstream>
#include <stdexcept>

#include "errsep/io/cnc/cnc_parameters.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/version.hpp"

namespace errsep::io {
namespace {

std::string lower_text(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

constexpr std::size_t kCurvePoints = 16;  // lincurve.comp: personality at most 16
constexpr std::size_t kDefaultPoints = 64;
constexpr std::size_t kMaxPoints = 16 * 15 + 1;  // 16 chained lincurves

// Curve i of a chain holds nodes [15 i, 15 i + 15] (neighbours share their joint node).
std::size_t curves_for(std::size_t nodes) {
  return nodes <= kCurvePoints ? 1 : (nodes - 2) / (kCurvePoints - 1) + 1;
}

class LinuxCncHal final : public CompensationWriter {
 public:
  CompensationFormat format() const override { return CompensationFormat::linuxcnc_hal; }
  std::string description() const override {
    return "LinuxCNC 2.9 HAL file: lincurve to the external offset, absolute in position";
  }
  const char* suffix() const override { return ".hal"; }
  std::vector<std::pair<std::string, std::string>> parameters() const override {
    return {
        {"input_pin", "HAL pin of the moving axis position in mm (default axis.<x>.pos-cmd)"},
        {"instance", "name prefix of the HAL components (default errsep-<symbol>)"},
        {"thread", "HAL thread (default servo-thread)"},
        {"scale_mm", "axis.<L>.eoffset-scale, mm per count (default 1e-6)"},
        {"points", "table points, 2.." + std::to_string(kMaxPoints) + " (default " +
                       std::to_string(kDefaultPoints) + "); more than 16 chain several lincurves"}};
  }

  struct Settings {
    std::string input_pin, instance, thread;
    double scale_mm = 1e-6;
    std::size_t points = kDefaultPoints;
  };
  Settings settings(const CncParameters& params, const core::MachineAxes* axes) const {
    const cnc::ParameterReader r(params, parameters(), to_string(format()));
    Settings s;
    s.input_pin = r.text("input_pin", std::string("axis.") +
                                          (axes ? cnc::lower(axes->input_axis) : 'x') + ".pos-cmd");
    s.instance =
        r.text("instance", "errsep-" + (axes ? lower_text(axes->symbol()) : std::string("comp")));
    s.thread = r.text("thread", "servo-thread");
    s.scale_mm = r.number("scale_mm", 1e-6, 1e-9, 1.0);
    s.points = static_cast<std::size_t>(
        r.integer("points", static_cast<long>(kDefaultPoints), 2, static_cast<long>(kMaxPoints)));
    for (const auto& [key, v] : {std::pair{"input_pin", s.input_pin},
                                 std::pair{"instance", s.instance}, std::pair{"thread", s.thread}})
      if (!cnc::plain_name(v)) r.fail(key, "'" + v + "' is not a HAL name");
    return s;
  }
  void validate(const CncParameters& params) const override { (void)settings(params, nullptr); }

  core::CompensationTable make_table(const core::CompensationProfile& profile,
                                     const CncParameters& params) const override {
    core::BreakpointOptions b;
    b.max_points = settings(params, &profile.axes).points;
    b.max_candidates = std::max(b.max_candidates, b.max_points);
    return core::make_breakpoint_table(profile, b);
  }

  std::vector<CncFile> write(const core::CompensationTable& table, const core::MachineAxes& axes,
                             const CncParameters& params, const CncWriteInfo& info) const override {
    const Settings s = settings(params, &axes);
    const std::size_t n = table.points();
    if (n < 2 || n > kMaxPoints)
      throw std::invalid_argument("LinuxCNC: " + std::to_string(n) + " points; 2.." +
                                  std::to_string(kMaxPoints) + " are written");
    const char l = cnc::lower(axes.output_axis);
    const char L = static_cast<char>(std::toupper(static_cast<unsigned char>(l)));
    const std::string& c = s.instance;
    const std::size_t k = curves_for(n);
    double max_slope = 0;
    for (std::size_t i = 1; i < n; ++i)
      max_slope = std::max(max_slope, std::abs((table.comp_um[i] - table.comp_um[i - 1]) * 1e-3 /
                                               (table.position_mm[i] - table.position_mm[i - 1])));
    const double counts_per_um = 1e-3 / s.scale_mm;
    auto counts = [&](double um) { return cnc::fixed(um * counts_per_um, 3); };
    auto curve = [&](std::size_t i) { return c + "-table" + std::to_string(i); };
    auto first = [&](std::size_t i) { return i * (kCurvePoints - 1); };
    auto last = [&](std::size_t i) { return std::min(n - 1, first(i) + kCurvePoints - 1); };
    std::ostringstream o;
    o << "# errsep " << kVersion << ": " << axes.symbol() << " straightness compensation of axis "
      << L << " as an absolute function of " << s.input_pin << " (" << n << " points in " << k
      << " lincurve" << (k > 1 ? "s" : "") << ")\n";
    if (!info.title.empty()) o << "# " << cnc::one_line(info.title) << "\n";
    o << "# compensation = -(measured error) at machine positions, applied as an external offset "
         "of axis "
      << L << ": actual = commanded + offset + error = commanded.\n";
    if (!info.accuracy_line.empty()) o << "# " << cnc::one_line(info.accuracy_line) << "\n";
    o << "# motion accumulates the CHANGES of axis." << l
      << ".eoffset-counts and zeroes the request at machine-on: the request is fed back\n"
         "# (counts += table(x) - request / scale each period, only while motion is enabled and "
         "homed), so it\n# equals the table at every position whatever the machine-on position "
         "(within 2 counts).\n";
    if (k > 1)
      o << "# lincurve holds 16 points: " << k << " curves share their end points and are "
        << "added, less the joint values\n# (each holds its end values outside its own range).\n";
    o << "# y-val and the sums are counts of axis." << l
      << ".eoffset-scale = " << format_number(s.scale_mm) << " mm.\n";
    o << "# The INI needs [AXIS_" << L
      << "]OFFSET_AV_RATIO > 0 (share of velocity/acceleration reserved for external offsets).\n";
    o << "# Largest slope of the table: " << format_number(max_slope) << " mm/mm; axis " << L
      << " must follow (slope) x (velocity of the moving axis).\n";
    o << "# If your HAL already loads lincurve, sum2, mux2, and2 or conv_float_s32, merge the "
         "names= lists; if\n# "
      << s.input_pin << ", axis." << l
      << ".eoffset-request, motion.motion-enabled or motion.is-all-homed is already on a signal,"
         "\n# net that signal instead (a pin is on one signal only).\n";
    std::string names, pers, sums;
    for (std::size_t i = 0; i < k; ++i) {
      names += (i ? "," : "") + curve(i);
      pers += (i ? "," : "") + std::to_string(last(i) - first(i) + 1);
      if (i > 0) sums += "," + c + "-sum" + std::to_string(i);
    }
    o << "loadrt lincurve names=" << names << " personality=" << pers << "\n";
    o << "loadrt sum2 names=" << c << "-err," << c << "-acc" << sums << "\n";
    o << "loadrt mux2 names=" << c << "-gate-err," << c << "-gate-acc\n";
    o << "loadrt and2 names=" << c << "-on\n";
    o << "loadrt conv_float_s32 names=" << c << "-s32\n";
    std::vector<std::string> functions;
    for (std::size_t i = 0; i < k; ++i)
      functions.push_back(curve(i));
    for (std::size_t i = 1; i < k; ++i)
      functions.push_back(c + "-sum" + std::to_string(i));
    for (const char* f : {"-on", "-err", "-gate-err", "-gate-acc", "-acc", "-s32"})
      functions.push_back(c + f);
    for (const auto& f : functions)
      o << "addf " << f << " " << s.thread << "\n";
    for (std::size_t i = 0; i < k; ++i)
      for (std::size_t j = first(i); j <= last(i); ++j) {
        char nn[8];
        std::snprintf(nn, sizeof nn, "%02zu", j - first(i));
        o << "setp " << curve(i) << ".x-val-" << nn << " " << cnc::fixed(table.position_mm[j], 6)
          << "\n";
        o << "setp " << curve(i) << ".y-val-" << nn << " " << counts(table.comp_um[j]) << "\n";
      }
    // sum_i = sum_{i-1} + table_i - table_i(its first node): each curve adds its own course.
    for (std::size_t i = 1; i < k; ++i)
      o << "setp " << c << "-sum" << i << ".offset " << counts(-table.comp_um[first(i)]) << "\n";
    o << "setp " << c << "-err.gain0 1\n";
    o << "setp " << c << "-err.gain1 " << format_number(-1.0 / s.scale_mm) << "\n";
    o << "setp " << c << "-gate-err.in0 0\n";
    o << "setp " << c << "-gate-acc.in0 0\n";
    o << "setp " << c << "-s32.clamp 1\n";
    o << "net " << c << "-pos " << s.input_pin << " =>";
    for (std::size_t i = 0; i < k; ++i)
      o << " " << curve(i) << ".in";
    o << "\n";
    std::string total = curve(0) + ".out";
    for (std::size_t i = 1; i < k; ++i) {
      const std::string sum = c + "-sum" + std::to_string(i);
      o << "net " << c << "-part" << i - 1 << " " << total << " => " << sum << ".in0\n";
      o << "net " << c << "-curve" << i << " " << curve(i) << ".out => " << sum << ".in1\n";
      total = sum + ".out";
    }
    o << "net " << c << "-table " << total << " => " << c << "-err.in0\n";
    o << "net " << c << "-request axis." << l << ".eoffset-request => " << c << "-err.in1\n";
    o << "net " << c << "-enabled motion.motion-enabled => " << c << "-on.in0\n";
    o << "net " << c << "-homed motion.is-all-homed => " << c << "-on.in1\n";
    o << "net " << c << "-active " << c << "-on.out => " << c << "-gate-err.sel " << c
      << "-gate-acc.sel\n";
    o << "net " << c << "-error " << c << "-err.out => " << c << "-gate-err.in1\n";
    o << "net " << c << "-step " << c << "-gate-err.out => " << c << "-acc.in1\n";
    o << "net " << c << "-counts-f " << c << "-acc.out => " << c << "-gate-acc.in1 " << c
      << "-s32.in\n";
    o << "net " << c << "-held " << c << "-gate-acc.out => " << c << "-acc.in0\n";
    o << "net " << c << "-counts " << c << "-s32.out => axis." << l << ".eoffset-counts\n";
    o << "setp axis." << l << ".eoffset-scale " << format_number(s.scale_mm) << "\n";
    o << "setp axis." << l << ".eoffset-enable 1\n";
    return {{axes.symbol() + "_linuxcnc.hal", o.str()}};
  }

  ControllerTable read(const std::string& text, const std::string& name) const override {
    std::istringstream in(text);
    std::string line;
    std::size_t no = 0;
    std::smatch m;
    const std::regex load_re(R"(^loadrt lincurve names=(\S+) personality=(\S+)$)");
    const std::regex val_re(R"(^setp (\S+)\.([xy])-val-(\d\d) (\S+)$)");
    const std::regex scale_re(R"(^setp axis\.([xyzabcuvw])\.eoffset-scale (\S+)$)");
    const std::regex in_re(R"(^net \S+ axis\.([xyz])\.pos-cmd => .*$)");
    const std::regex out_re(R"(^net \S+ \S+ => axis\.([xyz])\.eoffset-counts$)");
    std::vector<std::string> curves;
    std::vector<std::size_t> personality;
    std::map<std::string, std::map<std::size_t, double>> xs, ys;
    double scale = 0;
    ControllerTable ct;
    auto split = [](const std::string& t) {
      std::vector<std::string> v;
      std::stringstream ss(t);
      for (std::string item; std::getline(ss, item, ',');)
        v.push_back(item);
      return v;
    };
    while (std::getline(in, line)) {
      ++no;
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (std::regex_match(line, m, load_re)) {
        curves = split(m[1]);
        for (const auto& p : split(m[2])) {
          const double v = cnc::read_number(p, name, no);
          if (v != std::floor(v) || v < 2 || v > static_cast<double>(kCurvePoints))
            cnc::read_fail(name, no, "lincurve personality '" + p + "' is not 2..16");
          personality.push_back(static_cast<std::size_t>(v));
        }
        if (personality.size() != curves.size())
          cnc::read_fail(name, no, "one personality per lincurve needed");
      } else if (std::regex_match(line, m, val_re)) {
        (m[2] == "x" ? xs : ys)[m[1]][std::stoul(m[3])] = cnc::read_number(m[4], name, no);
      } else if (std::regex_match(line, m, scale_re)) {
        scale = cnc::read_number(m[2], name, no);
      } else if (std::regex_match(line, m, in_re)) {
        ct.input_axis = static_cast<char>(std::toupper(static_cast<unsigned char>(m[1].str()[0])));
      } else if (std::regex_match(line, m, out_re)) {
        ct.output_axis = static_cast<char>(std::toupper(static_cast<unsigned char>(m[1].str()[0])));
      }
    }
    if (curves.empty()) cnc::read_fail(name, 0, "no 'loadrt lincurve names=... personality=...'");
    if (!(scale > 0)) cnc::read_fail(name, 0, "no positive axis.L.eoffset-scale");
    for (std::size_t c = 0; c < curves.size(); ++c) {
      const std::size_t p = personality[c];
      for (std::size_t i = 0; i < p; ++i) {
        // lincurve parameters that are not set stay 0: a table must set all of them.
        if (!xs[curves[c]].count(i) || !ys[curves[c]].count(i))
          cnc::read_fail(name, 0, curves[c] + " point " + std::to_string(i) + " is not set");
        const double x = xs[curves[c]][i], y = ys[curves[c]][i] * scale * 1e3;
        auto& t = ct.table;
        if (c > 0 && i == 0) {  // the joint node the neighbours share
          if (t.position_mm.empty() || x != t.position_mm.back() || y != t.comp_um.back())
            cnc::read_fail(name, 0, curves[c] + " does not start where " + curves[c - 1] + " ends");
          continue;
        }
        if (!t.position_mm.empty() && !(x > t.position_mm.back()))
          cnc::read_fail(name, 0,
                         curves[c] + " x-val must increase (point " + std::to_string(i) + ")");
        t.position_mm.push_back(x);
        t.comp_um.push_back(y);
      }
    }
    ct.extra_um = 2 * scale * 1e3;  // the loop runs in whole counts
    return ct;
  }
};

}  // namespace

const CompensationWriter& linuxcnc_hal_writer() {
  static const LinuxCncHal w;
  return w;
}

}  // namespace errsep::io

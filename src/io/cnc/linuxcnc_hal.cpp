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
#include "errsep/version.hpp"

namespace errsep::io {
namespace {

std::string lower_text(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

std::string g(double v) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

class LinuxCncHal final : public CompensationWriter {
 public:
  CompensationFormat format() const override { return CompensationFormat::linuxcnc_hal; }
  std::string description() const override {
    return "LinuxCNC 2.9 HAL file: lincurve to the external offset, absolute in position";
  }
  const char* suffix() const override { return ".hal"; }
  std::vector<std::pair<std::string, std::string>> parameters() const override {
    return {{"input_pin", "HAL pin of the moving axis position in mm (default axis.<x>.pos-cmd)"},
            {"instance", "name prefix of the HAL components (default errsep-<symbol>)"},
            {"thread", "HAL thread (default servo-thread)"},
            {"scale_mm", "axis.<L>.eoffset-scale, mm per count (default 1e-6)"},
            {"points", "lincurve points, 2..16 (default 16)"}};
  }

  struct Settings {
    std::string input_pin, instance, thread;
    double scale_mm = 1e-6;
    std::size_t points = 16;
  };
  Settings settings(const CncParameters& params, const core::MachineAxes* axes) const {
    const cnc::ParameterReader r(params, parameters(), to_string(format()));
    Settings s;
    s.input_pin = r.text("input_pin", std::string("axis.") +
                                          (axes ? cnc::lower(axes->input_axis) : 'x') +
                                          ".pos-cmd");
    s.instance =
        r.text("instance", "errsep-" + (axes ? lower_text(axes->symbol()) : std::string("comp")));
    s.thread = r.text("thread", "servo-thread");
    s.scale_mm = r.number("scale_mm", 1e-6, 1e-9, 1.0);
    s.points = static_cast<std::size_t>(r.integer("points", 16, 2, 16));
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
    return core::make_breakpoint_table(profile, b);
  }

  std::vector<CncFile> write(const core::CompensationTable& table, const core::MachineAxes& axes,
                             const CncParameters& params,
                             const CncWriteInfo& info) const override {
    const Settings s = settings(params, &axes);
    const std::size_t n = table.points();
    if (n < 2 || n > 16)
      throw std::invalid_argument("LinuxCNC lincurve: " + std::to_string(n) +
                                  " points; the component holds 2..16");
    const char l = cnc::lower(axes.output_axis);
    const char L = static_cast<char>(std::toupper(static_cast<unsigned char>(l)));
    const std::string& c = s.instance;
    double max_slope = 0;
    for (std::size_t i = 1; i < n; ++i)
      max_slope = std::max(max_slope, std::abs((table.comp_um[i] - table.comp_um[i - 1]) * 1e-3 /
                                               (table.position_mm[i] - table.position_mm[i - 1])));
    const double counts_per_um = 1e-3 / s.scale_mm;
    std::ostringstream o;
    o << "# errsep " << kVersion << ": " << axes.symbol() << " straightness compensation of axis "
      << L << " as an absolute function of " << s.input_pin << " (lincurve, " << n
      << " points)\n";
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
    o << "# y-val are counts of axis." << l << ".eoffset-scale = " << g(s.scale_mm) << " mm.\n";
    o << "# The INI needs [AXIS_" << L
      << "]OFFSET_AV_RATIO > 0 (share of velocity/acceleration reserved for external offsets).\n";
    o << "# Largest slope of the table: " << g(max_slope) << " mm/mm; axis " << L
      << " must follow (slope) x (velocity of the moving axis).\n";
    o << "# If your HAL already loads lincurve, sum2, mux2, and2 or conv_float_s32, merge the "
         "names= lists.\n";
    o << "loadrt lincurve names=" << c << " personality=" << n << "\n";
    o << "loadrt sum2 names=" << c << "-err," << c << "-acc\n";
    o << "loadrt mux2 names=" << c << "-gate-err," << c << "-gate-acc\n";
    o << "loadrt and2 names=" << c << "-on\n";
    o << "loadrt conv_float_s32 names=" << c << "-s32\n";
    for (const std::string& f : {c, c + "-on", c + "-err", c + "-gate-err", c + "-gate-acc",
                                c + "-acc", c + "-s32"})
      o << "addf " << f << " " << s.thread << "\n";
    for (std::size_t i = 0; i < n; ++i) {
      char nn[8];
      std::snprintf(nn, sizeof nn, "%02zu", i);
      o << "setp " << c << ".x-val-" << nn << " " << cnc::fixed(table.position_mm[i], 6) << "\n";
      o << "setp " << c << ".y-val-" << nn << " "
        << cnc::fixed(table.comp_um[i] * counts_per_um, 3) << "\n";
    }
    o << "setp " << c << "-err.gain0 1\n";
    o << "setp " << c << "-err.gain1 " << g(-1.0 / s.scale_mm) << "\n";
    o << "setp " << c << "-gate-err.in0 0\n";
    o << "setp " << c << "-gate-acc.in0 0\n";
    o << "setp " << c << "-s32.clamp 1\n";
    o << "net " << c << "-pos " << s.input_pin << " => " << c << ".in\n";
    o << "net " << c << "-table " << c << ".out => " << c << "-err.in0\n";
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
    o << "setp axis." << l << ".eoffset-scale " << g(s.scale_mm) << "\n";
    o << "setp axis." << l << ".eoffset-enable 1\n";
    return {{axes.symbol() + "_linuxcnc.hal", o.str()}};
  }

  ControllerTable read(const std::string& text, const std::string& name) const override {
    std::istringstream in(text);
    std::string line;
    std::size_t no = 0;
    std::smatch m;
    const std::regex load_re(R"(^loadrt lincurve names=(\S+) personality=(\d+)$)");
    const std::regex val_re(R"(^setp (\S+)\.([xy])-val-(\d\d) (\S+)$)");
    const std::regex scale_re(R"(^setp axis\.([xyzabcuvw])\.eoffset-scale (\S+)$)");
    const std::regex in_re(R"(^net \S+ axis\.([xyz])\.pos-cmd => (\S+)\.in$)");
    const std::regex out_re(R"(^net \S+ \S+ => axis\.([xyz])\.eoffset-counts$)");
    std::string instance;
    std::size_t personality = 0;
    std::map<std::size_t, double> xs, ys;
    double scale = 0;
    ControllerTable ct;
    while (std::getline(in, line)) {
      ++no;
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (std::regex_match(line, m, load_re)) {
        instance = m[1];
        personality = std::stoul(m[2]);
      } else if (std::regex_match(line, m, val_re) && m[1] == instance) {
        (m[2] == "x" ? xs : ys)[std::stoul(m[3])] = cnc::read_number(m[4], name, no);
      } else if (std::regex_match(line, m, scale_re)) {
        scale = cnc::read_number(m[2], name, no);
      } else if (std::regex_match(line, m, in_re)) {
        ct.input_axis = static_cast<char>(std::toupper(static_cast<unsigned char>(m[1].str()[0])));
      } else if (std::regex_match(line, m, out_re)) {
        ct.output_axis = static_cast<char>(std::toupper(static_cast<unsigned char>(m[1].str()[0])));
      }
    }
    if (instance.empty()) cnc::read_fail(name, 0, "no 'loadrt lincurve names=... personality=N'");
    if (personality < 2 || personality > 16)
      cnc::read_fail(name, 0, "lincurve personality must be 2..16");
    if (!(scale > 0)) cnc::read_fail(name, 0, "no positive axis.L.eoffset-scale");
    for (std::size_t i = 0; i < personality; ++i) {
      // lincurve parameters that are not set stay 0: a table must set all of them.
      if (!xs.count(i) || !ys.count(i))
        cnc::read_fail(name, 0, "lincurve point " + std::to_string(i) + " is not set");
      if (i > 0 && !(xs[i] > xs[i - 1]))
        cnc::read_fail(name, 0, "lincurve x-val must increase (point " + std::to_string(i) + ")");
      ct.table.position_mm.push_back(xs[i]);
      ct.table.comp_um.push_back(ys[i] * scale * 1e3);
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

#include "errsep/io/cnc/sinumerik_cec.hpp"

#include <cmath>
#include <map>
#include <regex>
#include <sstream>
#include <stdexcept>

#include "errsep/io/cnc/cnc_parameters.hpp"
#include "errsep/version.hpp"

namespace errsep::io {
namespace {

constexpr std::size_t kDefaultMaxPoints = 200;  // 828D: MD18342 up to 200 per table

class SinumerikCec final : public CompensationWriter {
 public:
  CompensationFormat format() const override { return CompensationFormat::sinumerik_cec; }
  std::string description() const override {
    return "Siemens Sinumerik CEC (sag/angularity) table, NC program, values in mm";
  }
  const char* suffix() const override { return ".ini"; }
  std::vector<std::pair<std::string, std::string>> parameters() const override {
    auto p = cnc::uniform_table_parameters(kDefaultMaxPoints, "MD18342 $MN_MM_CEC_MAX_POINTS");
    p.insert(
        p.begin(),
        {{"input_axis", "machine axis name of the moving axis (default AX1/AX2/AX3 for X/Y/Z)"},
         {"output_axis", "machine axis name of the compensated axis (default AX<n>)"},
         {"table", "table index t of $AN_CEC[t,N] (default 0)"},
         {"direction", "$AN_CEC_DIRECTION: 0 both (default), 1 positive, -1 negative"}});
    return p;
  }

  struct Settings {
    std::string input, output;
    int table = 0, direction = 0;
    core::UniformTableOptions uniform;
  };
  Settings settings(const CncParameters& params, const core::MachineAxes* axes) const {
    const cnc::ParameterReader r(params, parameters(), to_string(format()));
    Settings s;
    s.input = r.text("input_axis",
                     axes ? "AX" + std::to_string(cnc::axis_number(axes->input_axis)) : "AX1");
    s.output = r.text("output_axis",
                      axes ? "AX" + std::to_string(cnc::axis_number(axes->output_axis)) : "AX2");
    if (!cnc::plain_name(s.input)) r.fail("input_axis", "'" + s.input + "' is not an axis name");
    if (!cnc::plain_name(s.output)) r.fail("output_axis", "'" + s.output + "' is not an axis name");
    if (s.input == s.output) r.fail("output_axis", "equals input_axis (" + s.input + ")");
    s.table = static_cast<int>(r.integer("table", 0, 0, 1000));
    s.direction = static_cast<int>(r.integer("direction", 0, -1, 1));
    s.uniform = cnc::uniform_table_options(r, kDefaultMaxPoints);
    return s;
  }
  void validate(const CncParameters& params) const override { (void)settings(params, nullptr); }

  core::CompensationTable make_table(const core::CompensationProfile& profile,
                                     const CncParameters& params) const override {
    return core::make_uniform_table(profile, settings(params, &profile.axes).uniform);
  }

  std::vector<CncFile> write(const core::CompensationTable& table, const core::MachineAxes& axes,
                             const CncParameters& params, const CncWriteInfo& info) const override {
    const Settings s = settings(params, &axes);
    const std::size_t n = table.points();
    if (n < 2 || !(table.step_mm > 0))
      throw std::invalid_argument("Sinumerik CEC: needs a uniform table of at least 2 points");
    const std::string t = std::to_string(s.table);
    const std::string idx = "[" + t + "]";
    std::ostringstream o;
    o << "%_N_NC_CEC_INI\n";
    o << "CHANDATA(1)\n";
    o << "; errsep " << kVersion << ": sag/angularity (CEC) table " << s.table + 1 << ", "
      << axes.symbol() << ": " << s.output << " compensated as a function of " << s.input << "\n";
    if (!info.title.empty()) o << "; " << cnc::one_line(info.title) << "\n";
    o << "; values in mm = -(measured straightness error) at machine positions of " << s.input
      << "; added to the " << s.output << " setpoint\n";
    if (!info.accuracy_line.empty()) o << "; " << cnc::one_line(info.accuracy_line) << "\n";
    o << "; needs MD18342 $MN_MM_CEC_MAX_POINTS[" << s.table << "] >= " << n
      << ", the CEC enable of " << s.output
      << " (MD32710) and the table enable (SD41300); check the K3 manual of your control\n";
    for (std::size_t i = 0; i < n; ++i)
      o << "$AN_CEC[" << t << "," << i << "]=" << cnc::fixed(table.comp_um[i] * 1e-3, 6) << "\n";
    o << "$AN_CEC_INPUT_AXIS" << idx << "=(" << s.input << ")\n";
    o << "$AN_CEC_OUTPUT_AXIS" << idx << "=(" << s.output << ")\n";
    // The step with 9 decimals: its rounding, times the number of points, stays below 1 nm.
    o << "$AN_CEC_STEP" << idx << "=" << cnc::fixed(table.step_mm, 9) << "\n";
    o << "$AN_CEC_MIN" << idx << "=" << cnc::fixed(table.position_mm.front(), 6) << "\n";
    o << "$AN_CEC_MAX" << idx << "=" << cnc::fixed(table.position_mm.back(), 6) << "\n";
    o << "$AN_CEC_DIRECTION" << idx << "=" << s.direction << "\n";
    o << "$AN_CEC_MULT_BY_TABLE" << idx << "=0\n";
    o << "$AN_CEC_IS_MODULO" << idx << "=0\n";
    o << "M17\n";
    return {{axes.symbol() + "_sinumerik_cec.ini", o.str()}};
  }

  ControllerTable read(const std::string& text, const std::string& name) const override {
    std::istringstream in(text);
    std::string line;
    std::size_t no = 0;
    const std::regex value_re(R"(^\$AN_CEC\[(\d+),(\d+)\]=(\S+)$)");
    const std::regex param_re(R"(^\$AN_CEC_([A-Z_]+)\[(\d+)\]=(.+)$)");
    std::map<std::size_t, double> values;
    std::map<std::string, std::string> param;
    int table = -1;
    std::smatch m;
    while (std::getline(in, line)) {
      ++no;
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (line.empty() || line[0] == ';' || line == "%_N_NC_CEC_INI" || line == "CHANDATA(1)" ||
          line == "M17")
        continue;
      int t = -1;
      if (std::regex_match(line, m, value_re)) {
        t = std::stoi(m[1]);
        if (!values.emplace(std::stoul(m[2]), cnc::read_number(m[3], name, no)).second)
          cnc::read_fail(name, no, "point " + m[2].str() + " given twice");
      } else if (std::regex_match(line, m, param_re)) {
        t = std::stoi(m[2]);
        param[m[1]] = m[3];
      } else {
        cnc::read_fail(name, no, "not a CEC line: '" + line + "'");
      }
      if (table >= 0 && t != table) cnc::read_fail(name, no, "more than one table in the file");
      table = t;
    }
    const std::size_t n = values.size();
    if (n < 2) cnc::read_fail(name, 0, "fewer than 2 $AN_CEC points");
    if (values.rbegin()->first != n - 1)
      cnc::read_fail(name, 0, "points are not 0.." + std::to_string(n - 1));
    for (const char* k : {"STEP", "MIN", "MAX"})
      if (!param.count(k)) cnc::read_fail(name, 0, std::string("$AN_CEC_") + k + " missing");
    const double step = cnc::read_number(param["STEP"], name, 0);
    const double mn = cnc::read_number(param["MIN"], name, 0);
    const double mx = cnc::read_number(param["MAX"], name, 0);
    if (!(step > 0)) cnc::read_fail(name, 0, "$AN_CEC_STEP must be > 0");
    if (std::abs(mn + step * static_cast<double>(n - 1) - mx) > 1e-6 * std::max(1.0, std::abs(mx)))
      cnc::read_fail(name, 0, "$AN_CEC_MAX != MIN + (points - 1) * STEP");
    ControllerTable ct;
    auto axis_of = [](const std::string& v) -> char {
      // "(X1)" or "(AX2)": the axis letter is not recoverable from a machine axis name in
      // general; AX1/AX2/AX3 are errsep's defaults for X/Y/Z.
      if (v == "(AX1)") return 'X';
      if (v == "(AX2)") return 'Y';
      if (v == "(AX3)") return 'Z';
      return 0;
    };
    ct.input_axis = axis_of(param["INPUT_AXIS"]);
    ct.output_axis = axis_of(param["OUTPUT_AXIS"]);
    ct.table.step_mm = step;
    for (std::size_t i = 0; i < n; ++i) {
      ct.table.position_mm.push_back(mn + step * static_cast<double>(i));
      ct.table.comp_um.push_back(values.at(i) * 1e3);
    }
    return ct;
  }
};

}  // namespace

const CompensationWriter& sinumerik_cec_writer() {
  static const SinumerikCec w;
  return w;
}

}  // namespace errsep::io

#include "errsep/io/cnc/beckhoff_crosscomp.hpp"

#include <cmath>
#include <map>
#include <regex>
#include <sstream>
#include <stdexcept>

#include "errsep/io/cnc/cnc_parameters.hpp"
#include "errsep/version.hpp"

namespace errsep::io {
namespace {

class BeckhoffCrosscomp final : public CompensationWriter {
 public:
  CompensationFormat format() const override { return CompensationFormat::beckhoff_crosscomp; }
  std::string description() const override {
    return "Beckhoff TwinCAT CNC kw.crosscomp list, 0.1 um";
  }
  const char* suffix() const override { return ".lis"; }
  std::vector<std::pair<std::string, std::string>> parameters() const override {
    auto p = cnc::uniform_table_parameters(0, "kw.crosscomp.last_index + 1");
    p.insert(p.begin(),
             {{"axis", "logical number of the compensated axis (default 1/2/3 for X/Y/Z)"},
              {"axis_name", "kopf.log_achs_name (default the axis letter)"},
              {"master_axis", "logical number of the moving axis (default 1/2/3 for X/Y/Z)"},
              {"n_cycles", "kw.crosscomp.n_cycles, smoothing cycles when switching on (10)"}});
    return p;
  }

  struct Settings {
    int axis = 2, master = 1, n_cycles = 10;
    std::string axis_name = "Y";
    core::UniformTableOptions uniform;
  };
  Settings settings(const CncParameters& params, const core::MachineAxes* axes) const {
    const cnc::ParameterReader r(params, parameters(), to_string(format()));
    Settings s;
    s.axis = static_cast<int>(
        r.integer("axis", axes ? cnc::axis_number(axes->output_axis) : 2, 1, 1000));
    s.master = static_cast<int>(
        r.integer("master_axis", axes ? cnc::axis_number(axes->input_axis) : 1, 1, 1000));
    if (s.master == s.axis) r.fail("master_axis", "equals axis (" + std::to_string(s.axis) + ")");
    s.axis_name = r.text("axis_name", axes ? std::string(1, axes->output_axis) : "Y");
    if (!cnc::plain_name(s.axis_name))
      r.fail("axis_name", "'" + s.axis_name + "' is not an axis name");
    s.n_cycles = static_cast<int>(r.integer("n_cycles", 10, 0, 1000000));
    s.uniform = cnc::uniform_table_options(r, 0);
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
    if (n < 2) throw std::invalid_argument("Beckhoff cross compensation: fewer than 2 points");
    std::ostringstream o;
    o << "# errsep " << kVersion << ": " << axes.symbol() << " cross compensation of axis "
      << s.axis_name << " as a function of logical axis " << s.master << "\n";
    if (!info.title.empty()) o << "# " << cnc::one_line(info.title) << "\n";
    o << "# setpoints: machine positions of axis " << s.master
      << "; corrections = -(measured error); both in 0.1 um\n";
    if (!info.accuracy_line.empty()) o << "# " << cnc::one_line(info.accuracy_line) << "\n";
    o << "kopf.achs_nr " << s.axis << "\n";
    o << "kopf.log_achs_name " << s.axis_name << "\n";
    o << "kw.crosscomp.last_index " << n - 1 << "\n";
    o << "kw.crosscomp.master_ax_nr " << s.master << "\n";
    o << "kw.crosscomp.unit 1\n";
    o << "kw.crosscomp.n_cycles " << s.n_cycles << "\n";
    o << "#\n";
    for (std::size_t i = 0; i < n; ++i) {
      o << "kw.crosscomp.table[" << i << "].setpoint " << std::llround(table.position_mm[i] * 1e4)
        << "\n";
      o << "kw.crosscomp.table[" << i << "].correction " << std::llround(table.comp_um[i] * 10)
        << "\n";
    }
    return {{axes.symbol() + "_beckhoff_crosscomp.lis", o.str()}};
  }

  ControllerTable read(const std::string& text, const std::string& name) const override {
    std::istringstream in(text);
    std::string line;
    std::size_t no = 0;
    std::smatch m;
    const std::regex kv_re(R"(^(\S+)\s+(\S+)\s*$)");
    const std::regex row_re(R"(^kw\.crosscomp\.table\[(\d+)\]\.(setpoint|correction)$)");
    std::map<std::size_t, double> sp, co;
    long last = -1, unit = -1;
    while (std::getline(in, line)) {
      ++no;
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (line.empty() || line[0] == '#') continue;
      if (!std::regex_match(line, m, kv_re))
        cnc::read_fail(name, no, "not 'key value': '" + line + "'");
      const std::string key = m[1], value = m[2];
      std::smatch r;
      if (std::regex_match(key, r, row_re))
        (r[2] == "setpoint" ? sp : co)[std::stoul(r[1])] = cnc::read_number(value, name, no);
      else if (key == "kw.crosscomp.last_index")
        last = std::lround(cnc::read_number(value, name, no));
      else if (key == "kw.crosscomp.unit")
        unit = std::lround(cnc::read_number(value, name, no));
    }
    if (unit != 1) cnc::read_fail(name, 0, "only kw.crosscomp.unit 1 (0.1 um) is read");
    if (last < 1 || static_cast<long>(sp.size()) != last + 1 ||
        static_cast<long>(co.size()) != last + 1)
      cnc::read_fail(name, 0, "kw.crosscomp.last_index does not match the table");
    ControllerTable ct;
    for (long i = 0; i <= last; ++i) {
      const auto k = static_cast<std::size_t>(i);
      if (!sp.count(k) || !co.count(k))
        cnc::read_fail(name, 0, "table[" + std::to_string(i) + "] incomplete");
      if (i > 0 && !(sp[k] > sp[k - 1])) cnc::read_fail(name, 0, "setpoints must increase");
      ct.table.position_mm.push_back(sp[k] * 1e-4);
      ct.table.comp_um.push_back(co[k] * 0.1);
    }
    return ct;
  }
};

}  // namespace

const CompensationWriter& beckhoff_crosscomp_writer() {
  static const BeckhoffCrosscomp w;
  return w;
}

}  // namespace errsep::io

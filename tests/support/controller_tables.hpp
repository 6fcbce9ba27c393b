#pragma once
// Independent readers of the controller compensation files errsep writes, and the interpolation
// each controller performs, written from the controllers' documentation (not from errsep's
// writers): the tests apply a file to a simulated error through these and look at the residual.
//
//  - Sinumerik CEC: value of point N at MIN + N * STEP, linear in between, first/last value
//    below MIN/above MAX; MAX must equal MIN + (points - 1) * STEP.
//  - LinuxCNC: lincurve's FUNCTION (src/hal/components/lincurve.comp: x >= x-val[last] gives the
//    last y, x <= x-val-00 the first, else linear), then conv_float_s32 (C conversion, i.e.
//    truncation toward zero, clamped), then external offset = counts * eoffset-scale.
//  - Beckhoff kw.crosscomp: (setpoint, correction) pairs in 0.1 um (unit 1), linear in between,
//    end values held outside (assumed, see errsep/io/controller_tables.hpp).
#include <cmath>
#include <cstdint>
#include <map>
#include <regex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace errsep::test {

struct CecTable {
  std::map<std::size_t, double> values_mm;  // point N -> value
  std::string input_axis, output_axis;
  double step_mm = 0, min_mm = 0, max_mm = 0;
  int direction = 99, is_modulo = -1;
  bool has_header = false, has_m17 = false;

  double apply_mm(double x_mm) const {
    const std::size_t n = values_mm.size();
    if (x_mm <= min_mm) return values_mm.at(0);
    if (x_mm >= max_mm) return values_mm.at(n - 1);
    const double p = (x_mm - min_mm) / step_mm;
    const auto i = static_cast<std::size_t>(std::floor(p));
    if (i + 1 >= n) return values_mm.at(n - 1);
    const double f = p - static_cast<double>(i);
    return values_mm.at(i) + f * (values_mm.at(i + 1) - values_mm.at(i));
  }
};

inline CecTable parse_sinumerik_cec(const std::string& text, int table_index = 0) {
  CecTable t;
  std::istringstream in(text);
  std::string line;
  const std::string ti = std::to_string(table_index);
  const std::regex value_re(R"(^\$AN_CEC\[)" + ti + R"(,(\d+)\]=(-?[0-9.]+)$)");
  const std::regex param_re(R"(^\$AN_CEC_([A-Z_]+)\[)" + ti + R"(\]=(.+)$)");
  std::smatch m;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == ';') continue;
    if (line == "%_N_NC_CEC_INI") {
      t.has_header = true;
      continue;
    }
    if (line == "CHANDATA(1)") continue;
    if (line == "M17") {
      t.has_m17 = true;
      continue;
    }
    if (std::regex_match(line, m, value_re)) {
      const auto n = static_cast<std::size_t>(std::stoul(m[1]));
      if (!t.values_mm.emplace(n, std::stod(m[2])).second)
        throw std::runtime_error("CEC: point " + m[1].str() + " given twice");
    } else if (std::regex_match(line, m, param_re)) {
      const std::string key = m[1], val = m[2];
      if (key == "INPUT_AXIS")
        t.input_axis = val;
      else if (key == "OUTPUT_AXIS")
        t.output_axis = val;
      else if (key == "STEP")
        t.step_mm = std::stod(val);
      else if (key == "MIN")
        t.min_mm = std::stod(val);
      else if (key == "MAX")
        t.max_mm = std::stod(val);
      else if (key == "DIRECTION")
        t.direction = std::stoi(val);
      else if (key == "IS_MODULO")
        t.is_modulo = std::stoi(val);
      else if (key == "MULT_BY_TABLE")
        continue;
      else
        throw std::runtime_error("CEC: unknown parameter " + key);
    } else {
      throw std::runtime_error("CEC: line not understood: '" + line + "'");
    }
  }
  const std::size_t n = t.values_mm.size();
  if (n < 2) throw std::runtime_error("CEC: fewer than 2 points");
  if (t.values_mm.rbegin()->first != n - 1) throw std::runtime_error("CEC: points not 0..n-1");
  if (!(t.step_mm > 0)) throw std::runtime_error("CEC: STEP missing or not positive");
  if (std::abs(t.min_mm + t.step_mm * static_cast<double>(n - 1) - t.max_mm) > 1e-3)
    throw std::runtime_error("CEC: MAX != MIN + (points-1)*STEP");
  return t;
}

struct LincurveHal {
  std::string instance;
  std::size_t personality = 0;
  std::vector<double> x, y;  // parameters as set
  double eoffset_scale = 0;
  bool enabled = false, clamp = false;
  std::string input_pin, output_pin;

  // lincurve.comp FUNCTION(_), then conv_float_s32, then counts * scale (mm).
  double apply_mm(double in) const {
    const std::size_t p = personality;
    double out;
    if (in >= x[p - 1]) {
      out = y[p - 1];
    } else if (in <= x[0]) {
      out = y[0];
    } else {
      std::size_t i = 0;
      while (in > x[i + 1])
        ++i;
      const double f = (in - x[i]) / (x[i + 1] - x[i]);
      out = y[i] + f * (y[i + 1] - y[i]);
    }
    double c = out;
    if (clamp) c = std::min(std::max(c, -2147483648.0), 2147483647.0);
    const auto counts = static_cast<std::int32_t>(c);  // C conversion truncates toward zero
    return enabled ? counts * eoffset_scale : 0.0;
  }
};

inline LincurveHal parse_lincurve_hal(const std::string& text) {
  LincurveHal h;
  std::istringstream in(text);
  std::string line;
  std::smatch m;
  std::map<std::string, std::string> net_from, net_to_conv, conv_to;
  std::string conv;
  std::map<std::size_t, double> xs, ys;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    if (std::regex_match(line, m,
                         std::regex(R"(^loadrt lincurve names=(\S+) personality=(\d+)$)"))) {
      h.instance = m[1];
      h.personality = std::stoul(m[2]);
    } else if (std::regex_match(line, m, std::regex(R"(^loadrt conv_float_s32 names=(\S+)$)"))) {
      conv = m[1];
    } else if (std::regex_match(line, m, std::regex(R"(^addf \S+ \S+$)"))) {
      continue;
    } else if (std::regex_match(line, m, std::regex(R"(^setp (\S+)\.([xy])-val-(\d\d) (\S+)$)"))) {
      if (m[1] != h.instance) throw std::runtime_error("lincurve: setp on unknown " + m[1].str());
      (m[2] == "x" ? xs : ys)[std::stoul(m[3])] = std::stod(m[4]);
    } else if (std::regex_match(line, m, std::regex(R"(^setp (\S+)\.clamp (\S+)$)"))) {
      h.clamp = m[2] == "1" || m[2] == "true" || m[2] == "TRUE";
    } else if (std::regex_match(line, m,
                                std::regex(R"(^setp axis\.([xyzabcuvw])\.eoffset-scale (\S+)$)"))) {
      h.eoffset_scale = std::stod(m[2]);
    } else if (std::regex_match(
                   line, m, std::regex(R"(^setp axis\.([xyzabcuvw])\.eoffset-enable (\S+)$)"))) {
      h.enabled = m[2] == "1" || m[2] == "true" || m[2] == "TRUE";
    } else if (std::regex_match(line, m, std::regex(R"(^net (\S+) (\S+) => (\S+)$)"))) {
      const std::string from = m[2], to = m[3];
      if (to == h.instance + ".in")
        h.input_pin = from;
      else if (from == h.instance + ".out" && to == conv + ".in")
        continue;
      else if (from == conv + ".out")
        h.output_pin = to;
      else
        throw std::runtime_error("lincurve: unexpected net '" + line + "'");
    } else {
      throw std::runtime_error("lincurve: line not understood: '" + line + "'");
    }
  }
  if (h.personality < 2 || h.personality > 16) throw std::runtime_error("lincurve: personality");
  for (std::size_t i = 0; i < h.personality; ++i) {
    // lincurve parameters that are not set stay 0: the reader insists on all of them.
    if (!xs.count(i) || !ys.count(i)) throw std::runtime_error("lincurve: point missing");
    h.x.push_back(xs[i]);
    h.y.push_back(ys[i]);
  }
  return h;
}

struct CrosscompList {
  int axis_number = 0, master_axis_number = 0, unit = -1;
  std::string axis_name;
  std::vector<double> setpoint_mm, correction_mm;

  double apply_mm(double x) const {
    const auto& s = setpoint_mm;
    const auto& c = correction_mm;
    if (x <= s.front()) return c.front();
    if (x >= s.back()) return c.back();
    std::size_t i = 0;
    while (x > s[i + 1])
      ++i;
    const double f = (x - s[i]) / (s[i + 1] - s[i]);
    return c[i] + f * (c[i + 1] - c[i]);
  }
};

inline CrosscompList parse_beckhoff_crosscomp(const std::string& text) {
  CrosscompList l;
  std::istringstream in(text);
  std::string line;
  std::smatch m;
  long last = -1;
  std::map<long, long long> sp, co;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    if (std::regex_match(line, m, std::regex(R"(^kopf\.achs_nr (\d+)$)")))
      l.axis_number = std::stoi(m[1]);
    else if (std::regex_match(line, m, std::regex(R"(^kopf\.log_achs_name (\S+)$)")))
      l.axis_name = m[1];
    else if (std::regex_match(line, m, std::regex(R"(^kw\.crosscomp\.last_index (\d+)$)")))
      last = std::stol(m[1]);
    else if (std::regex_match(line, m, std::regex(R"(^kw\.crosscomp\.master_ax_nr (\d+)$)")))
      l.master_axis_number = std::stoi(m[1]);
    else if (std::regex_match(line, m, std::regex(R"(^kw\.crosscomp\.unit (\d)$)")))
      l.unit = std::stoi(m[1]);
    else if (std::regex_match(line, m, std::regex(R"(^kw\.crosscomp\.n_cycles (\d+)$)")))
      continue;
    else if (std::regex_match(
                 line, m,
                 std::regex(R"(^kw\.crosscomp\.table\[(\d+)\]\.(setpoint|correction) (-?\d+)$)")))
      (m[2] == "setpoint" ? sp : co)[std::stol(m[1])] = std::stoll(m[3]);
    else
      throw std::runtime_error("crosscomp: line not understood: '" + line + "'");
  }
  if (l.unit != 1) throw std::runtime_error("crosscomp: only unit 1 (0.1 um) is read");
  if (last < 1 || static_cast<long>(sp.size()) != last + 1 ||
      static_cast<long>(co.size()) != last + 1)
    throw std::runtime_error("crosscomp: last_index does not match the table");
  for (long i = 0; i <= last; ++i) {
    l.setpoint_mm.push_back(static_cast<double>(sp.at(i)) * 1e-4);
    l.correction_mm.push_back(static_cast<double>(co.at(i)) * 1e-4);
    if (i > 0 && !(l.setpoint_mm[static_cast<std::size_t>(i)] >
                   l.setpoint_mm[static_cast<std::size_t>(i) - 1]))
      throw std::runtime_error("crosscomp: setpoints not increasing");
  }
  return l;
}

}  // namespace errsep::test

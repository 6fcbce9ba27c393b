#pragma once
// Independent readers of the controller compensation files errsep writes, and the interpolation
// each controller performs, written from the controllers' documentation (not from errsep's
// writers or readers): the tests apply a file to a simulated error through these.
//
//  - Sinumerik CEC: value of point N at MIN + N * STEP, linear in between, first/last value
//    below MIN/above MAX; MAX must equal MIN + (points - 1) * STEP.
//  - LinuxCNC: the HAL file is loaded into a small HAL network model (components lincurve,
//    sum2, mux2, and2, conv_float_s32 as their .comp sources define them; functions run in addf
//    order after motion) with a stand-in for motion's external offsets as src/emc/motion does
//    them: each period the change of axis.L.eoffset-counts times eoffset-scale is added to the
//    request, changes are dropped unless motion is enabled and all homed, and machine-on zeroes
//    the request.
//  - Beckhoff kw.crosscomp: (setpoint, correction) pairs in 0.1 um (unit 1), linear in between,
//    end values held outside (assumed, see errsep/io/cnc/beckhoff_crosscomp.hpp).
//  - HEIDENHAIN *.COM: "BEGIN <name>.COM MM", a line of column names, rows split by blanks,
//    "[END]"; AXISPOS and one axis column; the *.CMA names the *.COM in the moving axis's column
//    with '*' in ACTIVE.
//  - errsep CSV: "#" lines, the header x_mm,comp_um, comma-separated rows.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <map>
#include <random>
#include <regex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace errsep::test {

/// A measured straightness for table tests: 2..5 harmonics with random amplitudes, periods and
/// phases per seed, a tilt and an offset (the artefact's alignment), noise of 0.1 um on every
/// point; x every 5 mm over 305 mm; u = 0.1 um per point.
inline void random_straightness(std::uint32_t seed, std::vector<double>* x, std::vector<double>* s,
                                std::vector<double>* u) {
  constexpr double kPi = 3.14159265358979323846;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uni(0, 1);
  std::normal_distribution<double> noise(0, 0.1);
  const int h = 2 + static_cast<int>(uni(rng) * 4);
  std::vector<double> a(h), per(h), ph(h);
  for (int k = 0; k < h; ++k) {
    a[k] = 0.5 + 8 * uni(rng);
    per[k] = 15 + 500 * uni(rng);
    ph[k] = 2 * kPi * uni(rng);
  }
  x->clear();
  s->clear();
  u->clear();
  for (int i = 0; i * 5.0 <= 305 + 1e-9; ++i) {
    const double xi = i * 5.0;
    double v = 3.0 + 0.01 * xi + noise(rng);
    for (int k = 0; k < h; ++k)
      v += a[k] * std::sin(2 * kPi * xi / per[k] + ph[k]);
    x->push_back(xi);
    s->push_back(v);
    u->push_back(0.1);
  }
}

/// Linear between (xs, ys), end values held outside; xs increasing.
inline double hold_interp(const std::vector<double>& xs, const std::vector<double>& ys, double x) {
  if (x <= xs.front()) return ys.front();
  if (x >= xs.back()) return ys.back();
  std::size_t i = 0;
  while (x > xs[i + 1])
    ++i;
  const double f = (x - xs[i]) / (xs[i + 1] - xs[i]);
  return ys[i] + f * (ys[i + 1] - ys[i]);
}

inline std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) {
    if (!l.empty() && l.back() == '\r') l.pop_back();
    out.push_back(l);
  }
  return out;
}

// ---- Sinumerik CEC ----------------------------------------------------------------------------

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
  std::vector<double> nodes_mm() const {
    std::vector<double> v;
    for (std::size_t i = 0; i < values_mm.size(); ++i)
      v.push_back(min_mm + step_mm * static_cast<double>(i));
    return v;
  }
};

inline CecTable parse_sinumerik_cec(const std::string& text, int table_index = 0) {
  CecTable t;
  const std::string ti = std::to_string(table_index);
  const std::regex value_re(R"(^\$AN_CEC\[)" + ti + R"(,(\d+)\]=(-?[0-9.]+)$)");
  const std::regex param_re(R"(^\$AN_CEC_([A-Z_]+)\[)" + ti + R"(\]=(.+)$)");
  std::smatch m;
  for (const std::string& line : lines_of(text)) {
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
  if (std::abs(t.min_mm + t.step_mm * static_cast<double>(n - 1) - t.max_mm) > 1e-6)
    throw std::runtime_error("CEC: MAX != MIN + (points-1)*STEP");
  return t;
}

// ---- LinuxCNC HAL -----------------------------------------------------------------------------

/// A HAL file loaded into a model of the stock components it uses, with motion's external
/// offsets as a stand-in.  Signals carry doubles (bit = 0/1, s32 = whole numbers).
class HalNetwork {
 public:
  explicit HalNetwork(const std::string& text) {
    std::smatch m;
    const std::regex load_re(R"(^loadrt (\S+) names=(\S+)(?: personality=(\S+))?$)");
    const std::regex addf_re(R"(^addf (\S+) (\S+)$)");
    const std::regex setp_re(R"(^setp (\S+) (\S+)$)");
    const std::regex net_re(R"(^net (\S+) (\S+)((?: (?:=>|<=) \S+| \S+)*)$)");
    for (const std::string& line : lines_of(text)) {
      if (line.empty() || line[0] == '#') continue;
      if (std::regex_match(line, m, load_re)) {
        std::vector<std::string> names = split(m[2], ',');
        std::vector<std::string> pers =
            m[3].matched ? split(m[3], ',') : std::vector<std::string>{};
        for (std::size_t i = 0; i < names.size(); ++i) {
          Comp c{m[1], names[i], 0};
          if (c.type == "lincurve")
            c.personality = std::stoi(pers.at(std::min(i, pers.size() - 1)));
          else if (!known(c.type))
            throw std::runtime_error("HAL model: component '" + c.type + "' not modelled");
          comps_[names[i]] = c;
        }
      } else if (std::regex_match(line, m, addf_re)) {
        if (!comps_.count(m[1])) throw std::runtime_error("HAL: addf of unknown " + m[1].str());
        order_.push_back(m[1]);
      } else if (std::regex_match(line, m, setp_re)) {
        pins_[m[1]] = parse_value(m[2]);
      } else if (std::regex_match(line, m, net_re)) {
        const std::string sig = m[1];
        std::vector<std::string> pins = {m[2]};
        for (const auto& tok : split(std::string(m[3]), ' '))
          if (!tok.empty() && tok != "=>" && tok != "<=") pins.push_back(tok);
        for (const auto& p : pins) {
          if (net_of_.count(p)) throw std::runtime_error("HAL: pin " + p + " on two signals");
          net_of_[p] = sig;
        }
        if (!writers_.count(sig)) writers_[sig] = "";
        for (const auto& p : pins)
          if (is_output(p)) {
            if (!writers_[sig].empty()) throw std::runtime_error("HAL: two writers on " + sig);
            writers_[sig] = p;
          }
      } else {
        throw std::runtime_error("HAL: line not understood: '" + line + "'");
      }
    }
  }

  /// Value of a pin (through its signal if it is on one; unset = 0 as in HAL).
  double get(const std::string& pin) const {
    const auto n = net_of_.find(pin);
    if (n != net_of_.end()) {
      const auto s = signals_.find(n->second);
      return s == signals_.end() ? 0.0 : s->second;
    }
    const auto p = pins_.find(pin);
    return p == pins_.end() ? 0.0 : p->second;
  }
  void set(const std::string& pin, double v) {
    const auto n = net_of_.find(pin);
    if (n != net_of_.end())
      signals_[n->second] = v;
    else
      pins_[pin] = v;
  }
  bool connected(const std::string& pin) const { return net_of_.count(pin) > 0; }
  /// The pin that drives the signal `pin` is on ("" if none).
  std::string source_of(const std::string& pin) const {
    const auto n = net_of_.find(pin);
    return n == net_of_.end() ? std::string() : writers_.at(n->second);
  }
  /// Parameters of a lincurve instance.
  std::vector<double> lincurve_points(const std::string& inst, char xy) const {
    std::vector<double> v;
    for (int i = 0; i < comps_.at(inst).personality; ++i) {
      char key[64];
      std::snprintf(key, sizeof key, "%s.%c-val-%02d", inst.c_str(), xy, i);
      if (!pins_.count(key)) throw std::runtime_error(std::string("lincurve: ") + key + " unset");
      v.push_back(pins_.at(key));
    }
    return v;
  }
  const std::map<std::string, int> lincurves() const {
    std::map<std::string, int> out;
    for (const auto& [n, c] : comps_)
      if (c.type == "lincurve") out[n] = c.personality;
    return out;
  }

  /// One servo period: the functions in addf order (motion's own function runs first and is
  /// modelled by the caller through set()).
  void run_functions() {
    for (const auto& name : order_) {
      const Comp& c = comps_.at(name);
      const std::string& n = c.name;
      if (c.type == "lincurve") {
        // Its parameters are set once, when the file is loaded.
        auto it = curves_.find(n);
        if (it == curves_.end())
          it = curves_.emplace(n, std::make_pair(lincurve_points(n, 'x'), lincurve_points(n, 'y')))
                   .first;
        set(n + ".out", hold_interp(it->second.first, it->second.second, get(n + ".in")));
      } else if (c.type == "sum2") {  // out = in0 * gain0 + in1 * gain1 + offset
        set(n + ".out", get(n + ".in0") * param(n + ".gain0", 1.0) +
                            get(n + ".in1") * param(n + ".gain1", 1.0) + param(n + ".offset", 0));
      } else if (c.type == "mux2") {  // out = sel ? in1 : in0
        set(n + ".out", get(n + ".sel") != 0 ? get(n + ".in1") : get(n + ".in0"));
      } else if (c.type == "and2") {
        set(n + ".out", (get(n + ".in0") != 0 && get(n + ".in1") != 0) ? 1.0 : 0.0);
      } else if (c.type == "conv_float_s32") {  // C conversion truncates; clamp to s32
        double v = get(n + ".in");
        if (param(n + ".clamp", 0) != 0) v = std::min(std::max(v, -2147483648.0), 2147483647.0);
        set(n + ".out", static_cast<double>(static_cast<std::int32_t>(v)));
      }
    }
  }

 private:
  struct Comp {
    std::string type, name;
    int personality = 0;
  };
  static bool known(const std::string& t) {
    return t == "lincurve" || t == "sum2" || t == "mux2" || t == "and2" || t == "conv_float_s32";
  }
  static std::vector<std::string> split(const std::string& s, char sep) {
    std::vector<std::string> out;
    std::string cur;
    for (char ch : s) {
      if (ch == sep) {
        out.push_back(cur);
        cur.clear();
      } else {
        cur += ch;
      }
    }
    out.push_back(cur);
    return out;
  }
  static double parse_value(const std::string& v) {
    if (v == "true" || v == "TRUE") return 1;
    if (v == "false" || v == "FALSE") return 0;
    return std::stod(v);
  }
  bool is_output(const std::string& pin) const {
    // Component outputs, and motion's outputs (the stand-in writes them).
    for (const auto& [n, c] : comps_)
      if (pin == n + ".out") return true;
    return pin.rfind("motion.", 0) == 0 ||
           (pin.rfind("axis.", 0) == 0 && (pin.find(".pos-cmd") != std::string::npos ||
                                           pin.find(".eoffset-request") != std::string::npos));
  }
  double param(const std::string& pin, double dflt) const {
    const auto p = pins_.find(pin);
    return p == pins_.end() ? dflt : p->second;
  }

  std::map<std::string, Comp> comps_;
  std::vector<std::string> order_;
  std::map<std::string, double> pins_;  // unconnected pins and parameters
  std::map<std::string, std::string> net_of_, writers_;
  std::map<std::string, double> signals_;
  std::map<std::string, std::pair<std::vector<double>, std::vector<double>>> curves_;
};

/// motion's external offset of one axis as src/emc/motion does it (see the file comment).
struct EoffsetMotion {
  char input = 'x', output = 'y';
  bool on = false, homed = true;
  double request_mm = 0;
  long old_counts = 0;

  /// One period: position of the input axis, machine on or off; then the HAL functions.
  void period(HalNetwork& hal, double pos_mm, bool machine_on) {
    const std::string a = std::string("axis.") + output + ".";
    const long counts = static_cast<long>(hal.get(a + "eoffset-counts"));
    const long delta = counts - old_counts;
    old_counts = counts;
    if (machine_on && !on) request_mm = 0;  // machine-on zeroes the request
    on = machine_on;
    const bool enabled = hal.get(a + "eoffset-enable") != 0;
    if (enabled && hal.get(a + "eoffset-clear") == 0 && delta != 0 && homed && on)
      request_mm += delta * hal.get(a + "eoffset-scale");
    hal.set(a + "eoffset-request", request_mm);
    hal.set(std::string("axis.") + input + ".pos-cmd", pos_mm);
    hal.set("motion.motion-enabled", on ? 1 : 0);
    hal.set("motion.is-all-homed", homed ? 1 : 0);
    hal.run_functions();
  }
};

// ---- Beckhoff ---------------------------------------------------------------------------------

struct CrosscompList {
  int axis_number = 0, master_axis_number = 0, unit = -1;
  std::string axis_name;
  std::vector<double> setpoint_mm, correction_mm;
  double apply_mm(double x) const { return hold_interp(setpoint_mm, correction_mm, x); }
};

inline CrosscompList parse_beckhoff_crosscomp(const std::string& text) {
  CrosscompList l;
  std::smatch m;
  long last = -1;
  std::map<long, long long> sp, co;
  for (const std::string& line : lines_of(text)) {
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

// ---- HEIDENHAIN *.COM / *.CMA ------------------------------------------------------------------

struct TncTable {
  std::string name, unit;
  std::vector<std::string> columns;
  std::vector<std::size_t> column_start;  // where each name begins in the column line
  std::vector<std::vector<std::string>> rows;
  std::size_t column(const std::string& c) const {
    for (std::size_t i = 0; i < columns.size(); ++i)
      if (columns[i] == c) return i;
    throw std::runtime_error("TNC table " + name + ": no column " + c);
  }
};

/// Rows split at blanks; every cell must start in its column (fixed-width layout).
inline TncTable parse_tnc_table(const std::string& text) {
  const auto lines = lines_of(text);
  if (lines.size() < 3) throw std::runtime_error("TNC table: too short");
  std::smatch m;
  if (!std::regex_match(lines[0], m, std::regex(R"(^BEGIN (\S+)(?: (MM|INCH))?$)")))
    throw std::runtime_error("TNC table: first line is not 'BEGIN <name> [MM]'");
  TncTable t;
  t.name = m[1];
  t.unit = m[2];
  const std::regex word(R"(\S+)");
  for (auto it = std::sregex_iterator(lines[1].begin(), lines[1].end(), word);
       it != std::sregex_iterator(); ++it) {
    t.columns.push_back(it->str());
    t.column_start.push_back(static_cast<std::size_t>(it->position()));
  }
  bool ended = false;
  for (std::size_t k = 2; k < lines.size(); ++k) {
    if (lines[k] == "[END]") {
      ended = true;
      if (k + 1 != lines.size()) throw std::runtime_error("TNC table: lines after [END]");
      break;
    }
    std::vector<std::string> cells;
    std::size_t col = 0;
    for (auto it = std::sregex_iterator(lines[k].begin(), lines[k].end(), word);
         it != std::sregex_iterator(); ++it, ++col) {
      if (col >= t.columns.size() ||
          static_cast<std::size_t>(it->position()) != t.column_start[col])
        throw std::runtime_error("TNC table: row " + std::to_string(k + 1) +
                                 " does not line up with the columns");
      cells.push_back(it->str());
    }
    if (cells.size() != t.columns.size())
      throw std::runtime_error("TNC table: row " + std::to_string(k + 1) + " has " +
                               std::to_string(cells.size()) + " cells");
    t.rows.push_back(cells);
  }
  if (!ended) throw std::runtime_error("TNC table: no [END]");
  return t;
}

struct ComTable {
  char axis = 0;  // the compensated axis (its column)
  std::vector<double> axispos_mm, value_mm;
  double apply_mm(double x) const { return hold_interp(axispos_mm, value_mm, x); }
};

inline ComTable parse_heidenhain_com(const std::string& text) {
  const TncTable t = parse_tnc_table(text);
  if (t.unit != "MM") throw std::runtime_error("COM: not in MM");
  if (t.name.size() < 4 || t.name.substr(t.name.size() - 4) != ".COM")
    throw std::runtime_error("COM: name is not *.COM");
  ComTable c;
  const std::size_t nr = t.column("NR"), pos = t.column("AXISPOS");
  std::size_t val = t.columns.size();
  for (std::size_t i = 0; i < t.columns.size(); ++i)
    if (i != nr && i != pos && t.columns[i] != "BACKLASH") {
      if (val != t.columns.size()) throw std::runtime_error("COM: two axis columns");
      val = i;
    }
  if (val == t.columns.size() || t.columns[val].size() != 1)
    throw std::runtime_error("COM: no axis column");
  c.axis = t.columns[val][0];
  for (std::size_t r = 0; r < t.rows.size(); ++r) {
    if (std::stoul(t.rows[r][nr]) != r) throw std::runtime_error("COM: NR not 0, 1, 2, ...");
    c.axispos_mm.push_back(std::stod(t.rows[r][pos]));
    c.value_mm.push_back(std::stod(t.rows[r][val]));
    if (r > 0 && !(c.axispos_mm[r] > c.axispos_mm[r - 1]))
      throw std::runtime_error("COM: AXISPOS not increasing");
  }
  return c;
}

struct CmaAssignment {
  std::string column;  // the moving axis
  std::string com_path;
  bool active = false;
};

inline CmaAssignment parse_heidenhain_cma(const std::string& text) {
  const TncTable t = parse_tnc_table(text);
  if (t.name.size() < 4 || t.name.substr(t.name.size() - 4) != ".CMA")
    throw std::runtime_error("CMA: name is not *.CMA");
  if (t.rows.size() != 1 || t.columns.size() != 3)
    throw std::runtime_error("CMA: expected one line NR, <axis>, ACTIVE");
  CmaAssignment a;
  const std::size_t act = t.column("ACTIVE"), nr = t.column("NR");
  for (std::size_t i = 0; i < 3; ++i)
    if (i != act && i != nr) {
      a.column = t.columns[i];
      a.com_path = t.rows[0][i];
    }
  a.active = t.rows[0][act] == "*";
  return a;
}

// ---- errsep table CSV -------------------------------------------------------------------------

struct CsvCompTable {
  std::map<std::string, std::string> meta;
  std::vector<double> x_mm, comp_um;
  double apply_um(double x) const { return hold_interp(x_mm, comp_um, x); }
};

inline CsvCompTable parse_comp_csv(const std::string& text) {
  CsvCompTable c;
  bool header = false;
  for (const std::string& line : lines_of(text)) {
    if (line.empty()) continue;
    if (line[0] == '#') {
      const auto colon = line.find(':');
      if (colon != std::string::npos)
        c.meta[line.substr(2, colon - 2)] = line.substr(std::min(line.size(), colon + 2));
      continue;
    }
    if (!header) {
      if (line != "x_mm,comp_um") throw std::runtime_error("CSV: header '" + line + "'");
      header = true;
      continue;
    }
    const auto comma = line.find(',');
    c.x_mm.push_back(std::stod(line.substr(0, comma)));
    c.comp_um.push_back(std::stod(line.substr(comma + 1)));
  }
  return c;
}

}  // namespace errsep::test

#include "errsep/io/controller_tables.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "errsep/version.hpp"

namespace errsep::io {
namespace {

std::string fixed(double v, int decimals) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
  std::string s(buf);
  if (s == "-0" || s.find_first_not_of("-0.") == std::string::npos) {
    // "-0.000000" -> "0.000000"
    if (!s.empty() && s[0] == '-') s.erase(0, 1);
  }
  return s;
}

bool plain_name(const std::string& s) {
  if (s.empty()) return false;
  for (char c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.'))
      return false;
  return true;
}

// A comment text must not break out of its line.
std::string one_line(std::string s) {
  std::replace(s.begin(), s.end(), '\n', ' ');
  std::replace(s.begin(), s.end(), '\r', ' ');
  return s;
}

template <class Opts>
void require(const Opts& o, const char* what) {
  std::string why;
  if (!o.is_valid(&why)) throw std::invalid_argument(std::string(what) + ": " + why);
}

void require_table(std::size_t n, const char* what) {
  if (n < 2)
    throw std::invalid_argument(std::string(what) + ": a table needs at least 2 points, got " +
                                std::to_string(n));
}

}  // namespace

bool SinumerikCecOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (table_index < 0)
    return fail("table_index = " + std::to_string(table_index) + " must be >= 0");
  if (!plain_name(input_axis)) return fail("input_axis '" + input_axis + "' is not an axis name");
  if (!plain_name(output_axis))
    return fail("output_axis '" + output_axis + "' is not an axis name");
  if (input_axis == output_axis) return fail("input_axis and output_axis are both " + input_axis);
  if (direction < -1 || direction > 1)
    return fail("direction = " + std::to_string(direction) + " must be -1, 0 or 1");
  return true;
}

bool LinuxCncLincurveOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!plain_name(instance)) return fail("instance '" + instance + "' is not a HAL name");
  if (!plain_name(input_pin)) return fail("input_pin '" + input_pin + "' is not a HAL pin name");
  const char l = static_cast<char>(std::tolower(static_cast<unsigned char>(output_axis)));
  if (std::string("xyzabcuvw").find(l) == std::string::npos)
    return fail(std::string("output_axis '") + output_axis + "' is not one of XYZABCUVW");
  if (!(eoffset_scale_mm > 0) || !std::isfinite(eoffset_scale_mm))
    return fail("eoffset_scale_mm = " + std::to_string(eoffset_scale_mm) + " must be > 0");
  return true;
}

bool BeckhoffCrosscompOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (axis_number < 1)
    return fail("axis_number = " + std::to_string(axis_number) + " must be >= 1");
  if (master_axis_number < 1)
    return fail("master_axis_number = " + std::to_string(master_axis_number) + " must be >= 1");
  if (master_axis_number == axis_number)
    return fail("master_axis_number equals axis_number (" + std::to_string(axis_number) + ")");
  if (!plain_name(axis_name)) return fail("axis_name '" + axis_name + "' is not an axis name");
  if (n_cycles < 0) return fail("n_cycles = " + std::to_string(n_cycles) + " must be >= 0");
  return true;
}

std::string format_sinumerik_cec(const core::UniformCompensationTable& table,
                                 const SinumerikCecOptions& opts) {
  require(opts, "SinumerikCecOptions");
  require_table(table.comp_um.size(), "Sinumerik CEC");
  const int t = opts.table_index;
  const std::string idx = "[" + std::to_string(t) + "]";
  std::ostringstream o;
  o << "%_N_NC_CEC_INI\n";
  o << "CHANDATA(1)\n";
  o << "; errsep " << kVersion << ": sag/angularity (CEC) table " << t + 1 << ", "
    << opts.output_axis << " compensated as a function of " << opts.input_axis << "\n";
  if (!opts.title.empty()) o << "; " << one_line(opts.title) << "\n";
  o << "; values in mm = -(measured straightness error); added to the " << opts.output_axis
    << " setpoint\n";
  o << "; needs MD18342 $MN_MM_CEC_MAX_POINTS[" << t << "] >= " << table.comp_um.size()
    << ", the CEC enable of " << opts.output_axis
    << " (MD32710) and the table enable (SD41300); check the K3 manual of your control\n";
  for (std::size_t i = 0; i < table.comp_um.size(); ++i)
    o << "$AN_CEC[" << t << "," << i << "]=" << fixed(table.comp_um[i] * 1e-3, 6) << "\n";
  o << "$AN_CEC_INPUT_AXIS" << idx << "=(" << opts.input_axis << ")\n";
  o << "$AN_CEC_OUTPUT_AXIS" << idx << "=(" << opts.output_axis << ")\n";
  o << "$AN_CEC_STEP" << idx << "=" << fixed(table.step_mm, 4) << "\n";
  o << "$AN_CEC_MIN" << idx << "=" << fixed(table.start_mm, 4) << "\n";
  o << "$AN_CEC_MAX" << idx << "=" << fixed(table.end_mm(), 4) << "\n";
  o << "$AN_CEC_DIRECTION" << idx << "=" << opts.direction << "\n";
  o << "$AN_CEC_MULT_BY_TABLE" << idx << "=0\n";
  o << "$AN_CEC_IS_MODULO" << idx << "=0\n";
  o << "M17\n";
  return o.str();
}

std::string format_linuxcnc_lincurve_hal(const core::BreakpointTable& table,
                                         const LinuxCncLincurveOptions& opts) {
  require(opts, "LinuxCncLincurveOptions");
  const std::size_t n = table.x_mm.size();
  require_table(n, "LinuxCNC lincurve");
  if (n > 16)
    throw std::invalid_argument("LinuxCNC lincurve: " + std::to_string(n) +
                                " points, the component holds at most 16");
  for (std::size_t i = 1; i < n; ++i)
    if (!(table.x_mm[i] > table.x_mm[i - 1]))
      throw std::invalid_argument("LinuxCNC lincurve: breakpoints must increase (x[" +
                                  std::to_string(i) + "])");
  const char l = static_cast<char>(std::tolower(static_cast<unsigned char>(opts.output_axis)));
  const char L = static_cast<char>(std::toupper(static_cast<unsigned char>(l)));
  const std::string& c = opts.instance;
  const std::string conv = c + "-s32";
  double max_slope = 0;
  for (std::size_t i = 1; i < n; ++i)
    max_slope = std::max(max_slope, std::abs((table.comp_um[i] - table.comp_um[i - 1]) * 1e-3 /
                                             (table.x_mm[i] - table.x_mm[i - 1])));
  const double counts_per_um = 1e-3 / opts.eoffset_scale_mm;
  std::ostringstream o;
  o << "# errsep " << kVersion << ": straightness compensation of axis " << L
    << " as a function of " << opts.input_pin << " (lincurve, " << n << " points)\n";
  if (!opts.title.empty()) o << "# " << one_line(opts.title) << "\n";
  o << "# compensation = -(measured error), applied as an external offset of axis " << L
    << ": actual = commanded + offset + error = commanded.\n";
  o << "# Largest interpolation error of these points against the measured profile: "
    << fixed(table.max_interpolation_error_um, 3) << " um.\n";
  o << "# y-val are counts of axis." << l << ".eoffset-scale = " << opts.eoffset_scale_mm
    << " mm.\n";
  o << "# The INI needs [AXIS_" << L
    << "]OFFSET_AV_RATIO > 0 (share of velocity/acceleration reserved for external offsets).\n";
  o << "# Largest slope of the table: " << max_slope << " mm/mm; axis " << L
    << " must be able to follow (max slope) x (velocity of the moving axis).\n";
  o << "# If your HAL already loads lincurve or conv_float_s32, merge the names= lists.\n";
  o << "loadrt lincurve names=" << c << " personality=" << n << "\n";
  o << "loadrt conv_float_s32 names=" << conv << "\n";
  o << "addf " << c << " " << opts.thread << "\n";
  o << "addf " << conv << " " << opts.thread << "\n";
  for (std::size_t i = 0; i < n; ++i) {
    char nn[24];
    std::snprintf(nn, sizeof nn, "%02zu", i);
    o << "setp " << c << ".x-val-" << nn << " " << fixed(table.x_mm[i], 6) << "\n";
    o << "setp " << c << ".y-val-" << nn << " " << fixed(table.comp_um[i] * counts_per_um, 3)
      << "\n";
  }
  o << "setp " << conv << ".clamp 1\n";
  o << "net " << c << "-pos " << opts.input_pin << " => " << c << ".in\n";
  o << "net " << c << "-counts-f " << c << ".out => " << conv << ".in\n";
  o << "net " << c << "-counts " << conv << ".out => axis." << l << ".eoffset-counts\n";
  o << "setp axis." << l << ".eoffset-scale " << opts.eoffset_scale_mm << "\n";
  o << "setp axis." << l << ".eoffset-enable 1\n";
  return o.str();
}

std::string format_beckhoff_crosscomp(const core::UniformCompensationTable& table,
                                      const BeckhoffCrosscompOptions& opts) {
  require(opts, "BeckhoffCrosscompOptions");
  require_table(table.comp_um.size(), "Beckhoff cross compensation");
  std::ostringstream o;
  o << "# errsep " << kVersion << ": cross compensation of axis " << opts.axis_name
    << " as a function of logical axis " << opts.master_axis_number << "\n";
  if (!opts.title.empty()) o << "# " << one_line(opts.title) << "\n";
  o << "# corrections = -(measured error), in 0.1 um\n";
  o << "kopf.achs_nr " << opts.axis_number << "\n";
  o << "kopf.log_achs_name " << opts.axis_name << "\n";
  o << "kw.crosscomp.last_index " << table.comp_um.size() - 1 << "\n";
  o << "kw.crosscomp.master_ax_nr " << opts.master_axis_number << "\n";
  o << "kw.crosscomp.unit 1\n";
  o << "kw.crosscomp.n_cycles " << opts.n_cycles << "\n";
  o << "#\n";
  for (std::size_t i = 0; i < table.comp_um.size(); ++i) {
    const double x_mm = table.start_mm + table.step_mm * static_cast<double>(i);
    o << "kw.crosscomp.table[" << i << "].setpoint " << std::llround(x_mm * 1e4) << "\n";
    o << "kw.crosscomp.table[" << i << "].correction " << std::llround(table.comp_um[i] * 10)
      << "\n";
  }
  return o.str();
}

}  // namespace errsep::io

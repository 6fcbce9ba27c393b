#pragma once
// Compensation tables in the file formats CNC controllers load.  The tables themselves (values,
// sign convention: compensation = -error, added to the output axis command) come from
// errsep/core/compensation.hpp; this file only formats them.
//
// Formats and where they were confirmed:
//  - Siemens Sinumerik 840D/828D "sag/angularity compensation" (CEC, interpolatory compensation,
//    K3 function manual): $AN_CEC[t,N] values in mm, $AN_CEC_INPUT_AXIS (base axis, its setpoint
//    is the input), $AN_CEC_OUTPUT_AXIS (compensated axis), $AN_CEC_STEP, $AN_CEC_MIN,
//    $AN_CEC_MAX, $AN_CEC_DIRECTION (0 both directions), $AN_CEC_MULT_BY_TABLE, $AN_CEC_IS_MODULO;
//    values are interpolated linearly, the first/last value applies below MIN/above MAX.
//  - LinuxCNC: a joint's COMP_FILE only holds errors along the joint itself, so straightness goes
//    through the `lincurve` component (at most 16 points; below x-val-00 it returns y-val-00, above
//    the last x-val the last y-val; linear in between) feeding the output axis's external offset
//    (axis.L.eoffset-counts, s32, times axis.L.eoffset-scale) through `conv_float_s32`.  No
//    COMP_FILE is written (none of the errors here lies along the moving axis; EXX is not measured
//    by the four-sensor method).
//  - Beckhoff TwinCAT CNC cross compensation list (kw.crosscomp.*, infosys "Example for a
//    compensation list"): kopf.achs_nr / kopf.log_achs_name of the compensated axis,
//    kw.crosscomp.master_ax_nr, unit 1 = 0.1 um for setpoints and corrections, table[i].setpoint /
//    table[i].correction.  Not confirmed: the interpolation between and outside the points; we
//    assume linear inside and the end value held outside, like the two formats above.
//  - Heidenhain .COM (nonlinear axis error compensation, columns such as AXISPOS and the axis
//    name, or KinematicsComp with ISO 230-1 column names): the column layout of the table file
//    could not be confirmed from public material, so no writer is provided.
#include <filesystem>
#include <string>

#include "errsep/core/compensation.hpp"

namespace errsep::io {

struct SinumerikCecOptions {
  int table_index = 0;              ///< t in $AN_CEC[t, N] (table number = t + 1)
  std::string input_axis = "AX1";   ///< machine axis name of the moving (base) axis
  std::string output_axis = "AX2";  ///< machine axis name of the compensated axis
  int direction = 0;                ///< $AN_CEC_DIRECTION: 0 both, 1 positive, -1 negative
  std::string title;                ///< comment line (e.g. "EYX straightness, scan 2026-..")
  bool is_valid(std::string* why) const;
};

/// The CEC table as an NC program (%_N_NC_CEC_INI ... M17).  Values in mm with 6 decimals (1 nm).
std::string format_sinumerik_cec(const core::UniformCompensationTable& table,
                                 const SinumerikCecOptions& opts);

struct LinuxCncLincurveOptions {
  std::string instance = "errsep-comp";      ///< lincurve instance name (loadrt names=)
  std::string input_pin = "axis.x.pos-cmd";  ///< position of the moving axis, mm
  char output_axis = 'y';                    ///< axis letter whose external offset is fed
  std::string thread = "servo-thread";
  double eoffset_scale_mm = 1e-6;  ///< mm per count (1 nm)
  std::string title;               ///< first comment line
  bool is_valid(std::string* why) const;
};

/// HAL snippet: lincurve with the breakpoints (x in mm, y in counts of eoffset_scale_mm), a
/// conv_float_s32 to axis.<L>.eoffset-counts, eoffset-scale and eoffset-enable.  Comments say what
/// the INI needs ([AXIS_L]OFFSET_AV_RATIO) and the largest slope of the table.
std::string format_linuxcnc_lincurve_hal(const core::BreakpointTable& table,
                                         const LinuxCncLincurveOptions& opts);

struct BeckhoffCrosscompOptions {
  int axis_number = 2;          ///< logical number of the compensated axis (kopf.achs_nr)
  std::string axis_name = "Y";  ///< kopf.log_achs_name
  int master_axis_number = 1;   ///< logical number of the moving axis
  int n_cycles = 10;            ///< smoothing cycles when switching on (kw.crosscomp.n_cycles)
  std::string title;
  bool is_valid(std::string* why) const;
};

/// Cross-compensation list; setpoints and corrections in 0.1 um (kw.crosscomp.unit 1), rounded.
std::string format_beckhoff_crosscomp(const core::UniformCompensationTable& table,
                                      const BeckhoffCrosscompOptions& opts);

}  // namespace errsep::io

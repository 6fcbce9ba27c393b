#pragma once
// Siemens Sinumerik 840D sl / 828D "sag and angularity compensation" (CEC, interpolatory
// compensation; Siemens function manual "Extended Functions", K3 compensation): an NC program
// %_N_NC_CEC_INI with $AN_CEC[t,N] (values in mm), $AN_CEC_INPUT_AXIS[t] (base axis, its setpoint
// is the input), $AN_CEC_OUTPUT_AXIS[t] (compensated axis), $AN_CEC_STEP[t], $AN_CEC_MIN[t],
// $AN_CEC_MAX[t] (machine positions of the first and last point), $AN_CEC_DIRECTION[t] (0: both
// directions), $AN_CEC_MULT_BY_TABLE[t], $AN_CEC_IS_MODULO[t].  Values are interpolated linearly
// between points; below MIN / above MAX the first / last value applies.  The number of points per
// table is limited by MD18342 $MN_MM_CEC_MAX_POINTS[t] (828D: 200).
//
// Parameters: input_axis, output_axis (machine axis names; default AX1/AX2/AX3 for X/Y/Z),
// table (t, default 0), direction (-1, 0, 1), max_points (default 200), step_mm.
#include "errsep/io/cnc/compensation_format.hpp"

namespace errsep::io {

const CompensationWriter& sinumerik_cec_writer();

}  // namespace errsep::io

#pragma once
// Beckhoff TwinCAT CNC cross compensation list (axis compensation, kw.crosscomp.*; infosys
// "Example for a compensation list"): kopf.achs_nr / kopf.log_achs_name of the compensated axis,
// kw.crosscomp.master_ax_nr (the moving axis), kw.crosscomp.unit 1 = 0.1 um for setpoints and
// corrections, kw.crosscomp.last_index, kw.crosscomp.n_cycles, table[i].setpoint (machine position
// of the master axis) / table[i].correction.  Not confirmed from the documentation: the
// interpolation between and outside the points; errsep assumes linear inside and the end value
// held outside, as the CEC and TNC tables do.
//
// Parameters: axis (logical number of the compensated axis, default 1/2/3 for X/Y/Z), axis_name
// (default the letter), master_axis (logical number of the moving axis), n_cycles (default 10),
// max_points (default 0 = none), step_mm.
#include "errsep/io/cnc/compensation_format.hpp"

namespace errsep::io {

const CompensationWriter& beckhoff_crosscomp_writer();

}  // namespace errsep::io

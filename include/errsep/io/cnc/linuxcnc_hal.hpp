#pragma once
// LinuxCNC 2.9 (Debian 12 linuxcnc-uspace): straightness compensation as an external offset of
// the output axis, an absolute function of the input axis's commanded position, in stock HAL
// components only.
//
// Why not the obvious lincurve -> conv_float_s32 -> axis.L.eoffset-counts: motion takes the
// CHANGE of eoffset-counts each servo period (src/emc/motion: new - old counts, times
// eoffset-scale, added to the request), ignores changes while the machine is off or not homed,
// and zeroes the request at machine-on; an absolute table fed straight in is therefore shifted by
// its value at the position where the machine was switched on (or homed).  A joint's COMP_FILE
// cannot help: it holds errors along the joint itself.
//
// What is written instead (why stock components: a HAL file loads on any LinuxCNC 2.9 with
// nothing compiled or installed; a halcompile'd component would need linuxcnc-uspace-dev and an
// install into the realtime module directory on the machine):
//   lincurve      table(x): the breakpoints, x in machine mm, y in counts of eoffset-scale
//   sum2 err      table(x) - axis.L.eoffset-request / scale   (what the request still lacks)
//   mux2 (x2)     pass err and hold the accumulator only while motion is enabled and all homed
//                 (and2 of motion.motion-enabled, motion.is-all-homed); otherwise 0 (nothing
//                 accumulates while motion discards the changes)
//   sum2 acc      counts(k) = counts(k-1) + err: the change motion adds to the request is exactly
//                 what the request lacks, so one period later request = table(x)
//   conv_float_s32 -> axis.L.eoffset-counts
// The request then equals the table at the commanded position of one servo period before,
// whatever the machine-on position, to within 2 counts (whole counts; 2 nm at the default scale).
// lincurve holds at most 16 points (src/hal/components/lincurve.comp) and its end values outside
// its range: a longer table is split into curves that share their end points, whose outputs are
// added by sum2 less the joint values (sum2.offset), so that the sum follows each curve in turn.
//
// Parameters: input_pin (default axis.<input>.pos-cmd), instance (default errsep-<symbol>),
// thread (default servo-thread), scale_mm (eoffset-scale, default 1e-6), points (2..241,
// default 64: the breakpoints are chosen to make the largest interpolation error smallest).
#include "errsep/io/cnc/compensation_format.hpp"

namespace errsep::io {

const CompensationWriter& linuxcnc_hal_writer();

}  // namespace errsep::io

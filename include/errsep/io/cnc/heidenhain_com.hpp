#pragma once
// HEIDENHAIN TNC nonlinear axis error compensation: a compensation value table *.COM and its
// assignment *.CMA.  Sources (HEIDENHAIN technical manuals, chapter "Nonlinear axis error
// compensation"; MANUALplus 620 / TNC 620 NC software family, TNC 407 for the point limit):
//  - *.COM: column AXISPOS holds the compensation points, machine positions with respect to the
//    machine datum; optional column BACKLASH; the compensation values go into the column named
//    after the compensated axis (the axis key of CfgAxes/axisList).  Linear between points.
//  - *.CMA: "[axis in column from *.COM] = F(axis in column from *.CMA in which the *.COM is
//    entered)": the *.COM is entered in the column of the moving axis; an '*' in column ACTIVE
//    activates the line.  So EYX (Y error as a function of X, ISO 230-1) is column Y of a *.COM
//    entered in column X of the *.CMA -- the ISO 230-1 reading HEIDENHAIN itself recommends for
//    KinematicsComp (iTNC 530 HSCI technical manual: in the COM file of the X axis, EYX and EZX
//    are the straightness errors).  The *.COM is named after the ISO symbol (EYX.COM).
//  - at most 256 entries per *.COM (TNC 407 technical manual, module 9095, error 3).
//  - table text layout: "BEGIN <NAME>.<TYPE> MM", one line of left-aligned fixed-width column
//    names, fixed-width rows, "[END]" (as the controls write their tables).  No comment lines.
// Not confirmed from public material: columns literally named with ISO 230-1 symbols (EYX) in a
// *.COM; errsep writes the axis-named column the manuals describe.  Values in mm with 4 decimals
// (0.1 um, the TNC's input resolution for linear axes).
//
// Parameters: table_dir (path of the *.COM on the control, default TNC:\table\), max_points
// (default 256), step_mm.
#include "errsep/io/cnc/compensation_format.hpp"

namespace errsep::io {

const CompensationWriter& heidenhain_com_writer();

}  // namespace errsep::io

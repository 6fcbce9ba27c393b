#pragma once
// errsep's own compensation table: a CSV (errsep's convention, io/csv.hpp) with the columns
// x_mm (machine position of the input axis) and comp_um (compensation added to the output axis
// command), metadata naming the axes, the sign convention and the table's interpolation error.
// For controllers errsep has no writer for, and for errsep-devsim --compensation.
//
// Parameters: max_points (default 0 = none), step_mm.
#include "errsep/io/cnc/compensation_format.hpp"

namespace errsep::io {

const CompensationWriter& table_csv_writer();

}  // namespace errsep::io

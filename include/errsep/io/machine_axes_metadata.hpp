#pragma once
// Where a scan ran (core/machine_axes.hpp), recorded as "# key: value" metadata: in the raw scan
// (from the machine config) and carried into the result files, so that a result can be turned
// into tables in machine coordinates without the config at hand.
//   axis                    input axis (the moving axis), X/Y/Z
//   straightness_direction  output axis (the sensors' direction), X/Y/Z
//   slide_start_mm          machine position of the input axis at x = 0
//   scan_direction          +1 / -1
//   reading_sign            +1 / -1
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "errsep/core/machine_axes.hpp"

namespace errsep::io {

using Metadata = std::vector<std::pair<std::string, std::string>>;

Metadata machine_axes_metadata(const core::MachineAxes& axes);

/// The axes recorded in metadata, or nullopt when slide_start_mm, scan_direction or reading_sign
/// is absent (a result made before they were recorded, or by hand).  Throws
/// std::invalid_argument naming the key of a malformed value.
std::optional<core::MachineAxes> machine_axes_from_metadata(const Metadata& md);

}  // namespace errsep::io

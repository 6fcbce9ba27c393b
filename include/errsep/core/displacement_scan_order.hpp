#pragma once
// The order in which scan 2 of the one-axis displacement method reads its points (Haramiishi
// 2024, Eqs. 1-3; issue 16 item 4: measure so the missing effect shows).
//
//   forward   scan 2 in the order of scan 1 (the paper's plan): every point is read again the
//             same time after its first reading, so a drift linear in time is one constant in
//             the workpiece repeat S1_2 − S1_1 and is absorbed by its offset: not identifiable.
//   backward  scan 2 from the last point back to the first: the time between a point's two
//             readings changes along x, so sensor 1's linear drift shows in the repeat
//             (core/displacement_refine_one_axis.hpp).  The mean time of a point's two readings
//             is then the same at every point, so that drift also leaves w's shape alone
//             (w uses ½(S1_1 + S1_2), Eq. 1 read twice).
//
// One vocabulary: these names are the config's ([scan] scan2_order), the command line's and the
// raw file's ("# scan2_order:").
#include <string>

namespace errsep::core {

enum class DisplacementScanOrder { forward, backward };

const char* to_string(DisplacementScanOrder o) noexcept;
/// "forward" or "backward"; throws std::invalid_argument naming the accepted names.
DisplacementScanOrder displacement_scan_order_from_string(const std::string& name);
/// "forward, backward" (help texts and error messages).
const char* displacement_scan_order_names() noexcept;

}  // namespace errsep::core

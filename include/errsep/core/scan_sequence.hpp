#pragma once
// The order of the traverses of a four-sensor scan (issue 16, item 2: measure so the missing
// effect shows).
//
// The single-sensor system of Zhao et al. 2019 (section 2) moves one sensor to four
// configurations and traverses the slide once per configuration.  Eq. (1) assumes that nothing
// changes between those traverses.  A drift of the sensor in time, a warm-up, or a straightness
// that does not repeat then lies almost entirely in what one scan's model absorbs (S, γ and the
// zero-adjustment values e: see effect_drift.hpp, effect_thermal_drift.hpp, effect_traverse.hpp),
// so the residual stays white.  A sequence that measures a configuration twice makes the
// configuration disagree with itself by exactly such an effect:
//   single        1, 2, 3, 4 forward (the paper's scan, no redundancy)
//   closing pass  1, 2, 3, 4, then 1 again (a change between the first and the last traverse)
//   reversed      each configuration forward and back (a drift linear in time becomes a slope
//                 between the two directions that no zero-adjustment value can absorb)
//   reversed closing
//                 the reversed plan, then configuration 1 forward and back again at the end: a
//                 warm-up (a thermal drift, A·(1 − exp(−t/τ))) is all but settled by then, so
//                 configuration 1's first and last pairs differ by the drift's whole decay
//                 A·exp(−t/τ), which fixes τ and the form; the reversed pairs alone see only
//                 the drift's odd part about each pair's middle (2A·exp(−t_m/τ)·sinh(u/τ)),
//                 which a line fits about as well when τ is near a traverse's duration, while
//                 the even part (cosh) the pair's mean carries into S differs between the two
//                 forms (measured: with the reversed plan the form was told apart in 14 of 20
//                 runs at sigma 0.1, S halved in 10; with the closing pair S after equals the
//                 clean scan's error, refine_sweep)
//   interleaved   1, 2, 3, 4, 4, 3, 2, 1 (each configuration at two times symmetric about the
//                 middle of the scan)
//   rezeroed      1, 2, 3, 4, then 1, 2, 3, 4 again with the sensor re-zeroed by a stated offset
//                 Δ (moved in its holder): the same surface points read at a reading shifted by
//                 Δ.  S, f, γ repeat; a sensor non-linearity m = r + c₂·(r − mid)² does not: the
//                 two passes of a configuration differ by 2·c₂·Δ·r + const, a gain on the whole
//                 traverse that no zero adjustment absorbs (residual_trace.hpp).  The repeated
//                 traverses also show what the closing pass shows.
//   serpentine    1 forward, 2 back, 3 forward, 4 back, then 1 back: the slide never returns
//                 empty (the plan a machine runs fastest), and configuration 1 is read both ways,
//                 so a sensor's hysteresis (a reading lag of sign dr/dt) is determined by its two
//                 directions while configurations 2 and 4 read with the opposite lag, which S and
//                 γ absorb.  Its closing traverse also shows what the closing pass shows.
// Every traverse carries its start time and direction, so the reading times t(n, k) (P × T,
// column k = traverse k) follow from the slide speed, and time-dependent effects are modelled on
// them.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "errsep/core/four_sensor_config.hpp"

namespace errsep::core {

enum class TraverseDirection { forward, backward };
/// "forward" or "backward" (the raw file's and the reports' word).
const char* to_string(TraverseDirection d);
/// The inverse of to_string; false (d untouched) for any other text.
bool traverse_direction_from_string(const std::string& name, TraverseDirection* d);
/// The sign of the slide's velocity on such a traverse: +1 forward (x increasing), −1 backward.
inline double direction_sign(TraverseDirection d) {
  return d == TraverseDirection::forward ? 1.0 : -1.0;
}

struct Traverse {
  int configuration = 0;  ///< 0..3: configuration 1..4 of Eq. (1)
  TraverseDirection direction = TraverseDirection::forward;
  double start_s = 0.0;  ///< time of its first reading, from the start of the scan
  /// The sensor re-zeroed before this traverse: its readings shifted by this stated offset (µm)
  /// from traverse 1's zero (0: not re-zeroed).  The offset is what the user set, not a measured
  /// value: the fit gives such a traverse its own zero-adjustment unknown (repeat_keeps_zero
  /// notwithstanding); the reading level it reads at is what a non-linearity depends on.
  double zero_shift_um = 0.0;
};

enum class ScanSequenceKind {
  single,
  closing_pass,
  reversed,
  interleaved,
  rezeroed,
  serpentine,
  reversed_closing
};
const char* to_string(ScanSequenceKind k);
/// Every kind, single first, then the redundant plans in the order of the file comment (for
/// whatever goes through the plans: the sweep's choice of an identifying plan, its checks).
const std::vector<ScanSequenceKind>& all_scan_sequence_kinds();
/// The plan names a config or command line gives: "single", "closing" (or "closing pass"),
/// "reversed", "interleaved", "rezeroed", "serpentine", "reversed-closing" (or "reversed
/// closing").  Throws std::invalid_argument naming the
/// accepted names.
ScanSequenceKind scan_sequence_kind_from_string(const std::string& name);
/// "single, closing, reversed, interleaved, rezeroed, serpentine, reversed-closing" (for help
/// texts and error messages).
const char* scan_sequence_kind_names();

struct ScanSequence {
  std::vector<Traverse> traverses;
  std::string name = "custom";   ///< the kind's name when made by make()
  double speed_mm_per_s = 10.0;  ///< slide speed while reading
  /// Whether a configuration measured again reproduces its zero-adjustment value (a sensor stage
  /// that returns to the same position within noise).  False (the default): each repeated
  /// traverse has its own zero-adjustment unknown, the safe assumption for a stage that is moved
  /// away and back.
  bool repeat_keeps_zero = false;

  /// The reading times as measured (P × T, s since the start of the scan), or empty: then
  /// times_s() models them from start_s and the speed.  A scan's raw file records them
  /// (io::scan_sequence_of); a time-dependent effect is modelled on what was measured.
  Eigen::MatrixXd recorded_times_s;

  int size() const { return static_cast<int>(traverses.size()); }
  /// More traverses than configurations: some configuration is measured more than once.
  bool redundant() const { return size() > 4; }
  /// Some traverse is read with the sensor re-zeroed (Traverse::zero_shift_um != 0).
  bool rezeroed() const;
  /// Reading times t(n, k) in s, P × T: recorded_times_s when it has that shape, else traverse k
  /// reads x_n at start_s + (distance travelled since its first reading)/speed.
  Eigen::MatrixXd times_s(const FourSensorConfig& cfg) const;
  /// Every configuration at least once, configurations in 0..3, traverse 0 is configuration 1
  /// (its zero adjustment is the reference e_1 = 0), start times non-decreasing, speed > 0.
  bool is_valid(std::string* why = nullptr) const;

  /// The plans of the file comment; consecutive traverses follow each other after
  /// `turnaround_s` (moving the sensor stage, reversing the slide).  `rezero_offset_um`: the
  /// rezeroed plan's Δ (ignored by the others); it should be at least the readings' range
  /// so that the repeated pass reads at levels the first did not.
  static ScanSequence make(ScanSequenceKind kind, const FourSensorConfig& cfg,
                           double speed_mm_per_s = 10.0, double turnaround_s = 2.0,
                           double rezero_offset_um = 20.0);
};

}  // namespace errsep::core

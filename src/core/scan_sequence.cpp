#include "errsep/core/scan_sequence.hpp"

#include <array>
#include <cmath>
#include <stdexcept>

namespace errsep::core {

const char* to_string(ScanSequenceKind k) {
  switch (k) {
    case ScanSequenceKind::single:
      return "single";
    case ScanSequenceKind::closing_pass:
      return "closing pass";
    case ScanSequenceKind::reversed:
      return "reversed";
    case ScanSequenceKind::interleaved:
      return "interleaved";
    case ScanSequenceKind::rezeroed:
      return "rezeroed";
    case ScanSequenceKind::serpentine:
      return "serpentine";
    case ScanSequenceKind::reversed_closing:
      return "reversed closing";
  }
  return "unknown";
}

const std::vector<ScanSequenceKind>& all_scan_sequence_kinds() {
  static const std::vector<ScanSequenceKind> kinds = {
      ScanSequenceKind::single,      ScanSequenceKind::closing_pass,
      ScanSequenceKind::reversed,    ScanSequenceKind::reversed_closing,
      ScanSequenceKind::interleaved, ScanSequenceKind::rezeroed,
      ScanSequenceKind::serpentine};
  return kinds;
}

const char* to_string(TraverseDirection d) {
  return d == TraverseDirection::forward ? "forward" : "backward";
}

bool traverse_direction_from_string(const std::string& name, TraverseDirection* d) {
  for (const auto k : {TraverseDirection::forward, TraverseDirection::backward})
    if (name == to_string(k)) {
      *d = k;
      return true;
    }
  return false;
}

const char* scan_sequence_kind_names() {
  return "single, closing, reversed, interleaved, rezeroed, serpentine, reversed-closing";
}

ScanSequenceKind scan_sequence_kind_from_string(const std::string& name) {
  if (name == "single") return ScanSequenceKind::single;
  if (name == "closing" || name == "closing pass") return ScanSequenceKind::closing_pass;
  if (name == "reversed") return ScanSequenceKind::reversed;
  if (name == "interleaved") return ScanSequenceKind::interleaved;
  if (name == "rezeroed" || name == "re-zeroed") return ScanSequenceKind::rezeroed;
  if (name == "serpentine") return ScanSequenceKind::serpentine;
  if (name == "reversed-closing" || name == "reversed closing")
    return ScanSequenceKind::reversed_closing;
  throw std::invalid_argument("unknown scan plan '" + name + "': one of " +
                              scan_sequence_kind_names());
}

Eigen::MatrixXd ScanSequence::times_s(const FourSensorConfig& cfg) const {
  const int P = cfg.positions();
  if (recorded_times_s.rows() == P && recorded_times_s.cols() == size()) return recorded_times_s;
  Eigen::MatrixXd t(P, size());
  for (int k = 0; k < size(); ++k) {
    const Traverse& tr = traverses[static_cast<std::size_t>(k)];
    for (int n = 0; n < P; ++n) {
      const int steps = direction_sign(tr.direction) > 0 ? n : P - 1 - n;
      t(n, k) = tr.start_s + steps * cfg.dx_mm / speed_mm_per_s;
    }
  }
  return t;
}

bool ScanSequence::rezeroed() const {
  for (const Traverse& tr : traverses)
    if (tr.zero_shift_um != 0.0) return true;
  return false;
}

bool ScanSequence::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(speed_mm_per_s > 0))
    return fail("speed_mm_per_s = " + std::to_string(speed_mm_per_s) + ": must be > 0");
  if (traverses.empty() || traverses.front().configuration != 0)
    return fail("traverse 1 must measure configuration 1 (the zero-adjustment reference)");
  if (traverses.front().zero_shift_um != 0.0)
    return fail("traverse 1 defines the sensor's zero: its zero shift must be 0");
  std::array<bool, 4> seen{};
  for (std::size_t k = 0; k < traverses.size(); ++k) {
    const int c = traverses[k].configuration;
    if (c < 0 || c > 3)
      return fail("traverse " + std::to_string(k + 1) + ": configuration " + std::to_string(c) +
                  " not in 0..3");
    seen[static_cast<std::size_t>(c)] = true;
    if (!std::isfinite(traverses[k].zero_shift_um))
      return fail("traverse " + std::to_string(k + 1) + ": zero shift must be finite");
    if (k > 0 && traverses[k].start_s < traverses[k - 1].start_s)
      return fail("traverse " + std::to_string(k + 1) + " starts before traverse " +
                  std::to_string(k));
  }
  for (std::size_t c = 0; c < 4; ++c)
    if (!seen[c]) return fail("configuration " + std::to_string(c + 1) + " is never measured");
  return true;
}

ScanSequence ScanSequence::make(ScanSequenceKind kind, const FourSensorConfig& cfg,
                                double speed_mm_per_s, double turnaround_s,
                                double rezero_offset_um) {
  if (!(speed_mm_per_s > 0) || !(turnaround_s >= 0))
    throw std::invalid_argument("scan sequence: speed must be > 0 and turnaround >= 0");
  if (kind == ScanSequenceKind::rezeroed &&
      !(std::isfinite(rezero_offset_um) && rezero_offset_um != 0.0))
    throw std::invalid_argument("scan sequence: the rezeroed plan needs a finite, non-zero offset");
  using D = TraverseDirection;
  std::vector<std::pair<int, D>> order;
  switch (kind) {
    case ScanSequenceKind::single:
      order = {{0, D::forward}, {1, D::forward}, {2, D::forward}, {3, D::forward}};
      break;
    case ScanSequenceKind::closing_pass:
      order = {{0, D::forward}, {1, D::forward}, {2, D::forward}, {3, D::forward}, {0, D::forward}};
      break;
    case ScanSequenceKind::reversed:
    case ScanSequenceKind::reversed_closing:
      for (int c = 0; c < 4; ++c) {
        order.push_back({c, D::forward});
        order.push_back({c, D::backward});
      }
      if (kind == ScanSequenceKind::reversed_closing) {
        order.push_back({0, D::forward});
        order.push_back({0, D::backward});
      }
      break;
    case ScanSequenceKind::interleaved:
      for (int c : {0, 1, 2, 3, 3, 2, 1, 0})
        order.push_back({c, D::forward});
      break;
    case ScanSequenceKind::rezeroed:
      for (int c : {0, 1, 2, 3, 0, 1, 2, 3})
        order.push_back({c, D::forward});
      break;
    case ScanSequenceKind::serpentine:
      order = {
          {0, D::forward}, {1, D::backward}, {2, D::forward}, {3, D::backward}, {0, D::backward}};
      break;
  }
  ScanSequence s;
  s.speed_mm_per_s = speed_mm_per_s;
  s.name = to_string(kind);
  const double duration = (cfg.positions() - 1) * cfg.dx_mm / speed_mm_per_s;
  double t = 0.0;
  for (std::size_t k = 0; k < order.size(); ++k) {
    // The rezeroed plan's second pass (traverses 5..8) reads with the sensor shifted by Δ.
    const double shift = kind == ScanSequenceKind::rezeroed && k >= 4 ? rezero_offset_um : 0.0;
    s.traverses.push_back({order[k].first, order[k].second, t, shift});
    t += duration + turnaround_s;
  }
  return s;
}

}  // namespace errsep::core

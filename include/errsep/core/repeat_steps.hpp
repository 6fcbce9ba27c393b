#pragma once
// A knocked sensor told apart by a configuration measured twice (issue 16, item 3).
//
// From one scan of the four configurations a step in the readings of configuration c from
// position k on cannot be attributed: per position the model absorbs everything affine in the
// offsets O_i (S, γ), and f — free per sample — absorbs in the two remaining directions a change
// of its curvature (f = (j − j₀)₊² adds the constant Σ_i V₂ᵀe_i·k_i² from the last offset on).
// So far from the step every configuration's step column leaves the same one residual direction,
// and the four candidates differ only in the few positions between their offsets (the
// ambiguity gross_errors.hpp reports).
//
// A plan that measures a configuration again (reversed, interleaved, closing pass: scan_sequence
// .hpp) removes it.  The sensor stays knocked, so a knock during traverse K from position n₀ on
// offsets traverse K from n₀ (in its direction of travel) and every later traverse entirely.
// The difference of two traverses of one configuration is then a step at n₀ if the knock fell
// between or on them, and a constant otherwise; f, S, γ cancel in it (they repeat), so the step
// is seen with all P positions and nothing of the model absorbs it.  The difference of a
// configuration whose two traverses are both before or both after the knock holds no step.
//
// For each configuration measured more than once, each difference of consecutive traverses of
// it is detrended (Legendre polynomial of degree `detrend_degree` in position: a drift linear in
// time is linear in x on a traverse) and searched for one step: for each candidate k the
// likelihood ratio z_k = |wₖᵀd|/σ̂_k (wₖ the normalised detrended step column, σ̂_k of the
// difference with that step in it).  The largest z over the candidates and the differences is
// tested against its distribution under the model, found by Monte-Carlo draws of independent
// noise on every reading of the sequence (exact for Gaussian noise; scale-free).  A found step is
// attributed to its configuration when its z² exceeds the best z² of every other configuration's
// difference by attribution_chi2 (likelihood ratio, as gross_errors.hpp).
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "errsep/core/four_sensor_config.hpp"
#include "errsep/core/scan_sequence.hpp"

namespace errsep::core {

struct RepeatStepOptions {
  double alpha = 0.01;
  int min_segment = 3;             ///< a step leaves at least this many positions on each side
  int detrend_degree = 1;          ///< polynomial in position removed from each difference
  int mc_samples = 400;            ///< Monte-Carlo draws of the sequence's noise
  std::uint64_t seed = 17;         ///< fixed: the same data give the same report
  double attribution_chi2 = 6.63;  ///< χ²₁(0.99), as GrossErrorOptions
  bool is_valid(std::string* why = nullptr) const;
};

struct RepeatStepScan {
  std::vector<int> repeated;  ///< configurations (0-based) measured more than once
  std::string not_tested;     ///< why not (no configuration measured twice)
  bool found = false;         ///< p_value < alpha
  int configuration = -1;     ///< of the largest step (0-based)
  int position = -1;          ///< first position of the step (n >= position differ)
  /// The two traverses (0-based, earlier and later) of `configuration` whose difference holds
  /// the step: the knock fell in one of them (file comment).
  int earlier_traverse = -1, later_traverse = -1;
  double x_mm = 0;
  double size_um = 0, u_size_um = 0;  ///< of the later traverse minus the earlier
  double z = 0;                       ///< its likelihood-ratio statistic
  double rival_z = 0;                 ///< the best of the other configurations' differences
  double p_value = 1;                 ///< Monte-Carlo p-value of the largest z
  bool attributed = false;            ///< z² − rival_z² >= attribution_chi2
  std::string finding;                ///< one line when found
};

/// Searches `m_um` (P × T, column k = traverse k of `seq`, each row one slide position).
/// Throws std::invalid_argument for shape mismatches or invalid options.
RepeatStepScan find_repeat_steps(const FourSensorConfig& cfg, const ScanSequence& seq,
                                 const Eigen::MatrixXd& m_um, const RepeatStepOptions& opts = {});

}  // namespace errsep::core

#pragma once
// The straightness trend of one machine over its past scans, from the local results store
// (io/results_store.hpp): the ISO 230-1 straightness (minimum zone) and its expanded uncertainty
// U (k = 2) that the daemon wrote in each result file's metadata, in scan order, and whether it
// changed significantly.
//
// A change between two scans is significant when |t_b − t_a| > U_c = sqrt(U_a² + U_b²): the
// expanded uncertainty of the difference of two independent results (k = 2).  Taking them as
// independent ignores what the scans share (the same sensors, the same geometry); a shared
// systematic part cancels in the difference, so U_c is on the safe side (a flagged change is
// real at about 95 %, a small real change may go unflagged).  Each scan is compared with the one
// before it and with the first scan of the store (the baseline: a slideway that wears slowly
// drifts by less than U_c per scan and only shows against it).  The minimum-zone figure of a
// noisy profile is biased upwards by the noise (it is a maximum): a scan with more noise reads
// higher; σ̂ of each scan is listed so that a reader can tell.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "errsep/io/csv.hpp"

namespace errsep::io {

struct TrendPoint {
  std::string scan_id;  ///< store stem
  std::uint64_t scan_number = 0;
  std::string started_utc;
  double straightness_um = 0;  ///< minimum zone
  double U_um = 0;             ///< its expanded uncertainty (k = 2)
  double sigma_hat_um = 0;     ///< NaN when the result does not say
  /// Against the previous scan (0 for the first).
  double change_um = 0, change_U_um = 0;
  bool significant = false;
  /// Against the first scan (the baseline).
  double drift_um = 0, drift_U_um = 0;
  bool drift_significant = false;
};

struct StraightnessTrend {
  std::vector<TrendPoint> points;    ///< in scan-number order
  std::vector<std::string> skipped;  ///< result files without a usable straightness, and why
  /// True when any step or the drift of the last scan against the first is significant.
  bool any_significant() const;
};

/// Reads every result file of the store in `results_dir`.  Throws std::runtime_error when the
/// directory cannot be read.  Results without straightness metadata are listed in `skipped`.
StraightnessTrend straightness_trend(const std::filesystem::path& results_dir);

/// One row per scan: scan_number, straightness_um, U_um, sigma_hat_um (when every result has
/// it), change_um, change_U_um, significant (0/1), drift_um, drift_U_um, drift_significant (0/1);
/// scan ids in metadata.
CsvTable trend_table(const StraightnessTrend& t);
/// The trend as text lines (for evaluation.txt): one line per scan, flagged changes marked.
std::string format_trend(const StraightnessTrend& t);

}  // namespace errsep::io

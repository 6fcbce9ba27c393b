#pragma once
// Four-sensor readings for a scan sequence (scan_sequence.hpp): Eq. (1) of Zhao et al. 2019 per
// traverse, independent noise σ on every reading, and effects that change with time or from one
// traverse to the next, which a sequence with redundancy can reveal (issue 16, item 2):
//   linear drift      m += a_c·t                      (rate a_c of the sensor in configuration c)
//   thermal drift     m += A_c·(1 − exp(−t/τ))        (warm-up from the start of the scan)
//   non-repeating S   m += ΔS(k, x)                   (the slide bends differently on traverse k)
// and a re-zeroed traverse (Traverse::zero_shift_um = Δ) reads u = (Eq. 1) + Δ.  A sensor
// non-linearity acts on the whole reading, offset included: m = u + c₂·(u − mid)² (not in the
// effect library; what the rezeroed plan makes show, scan_sequence.hpp).  A sensor hysteresis h
// lags the reading behind its change: m −= h·sign(dr/dt), the sign from the noise-free readings'
// change along the traverse in time (what a plan reading a configuration both ways reveals:
// reversed, serpentine).
// The truth S is the first traverse's (ΔS(0, x) should be 0: the scan refers to its first pass).
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <functional>

#include "errsep/core/four_sensor_config.hpp"
#include "errsep/core/four_sensor_model.hpp"
#include "errsep/core/scan_sequence.hpp"

namespace errsep::core {

struct SequenceEffects {
  std::array<double, 4> drift_um_per_s{0, 0, 0, 0};  ///< a_c per configuration
  std::array<double, 4> thermal_um{0, 0, 0, 0};      ///< A_c per configuration
  double thermal_tau_s = 40.0;
  /// ΔS(k, x_mm) in µm for traverse k (0-based); empty = S repeats.
  std::function<double(int traverse, double x_mm)> S_change_um;
  /// The sensor's non-linearity: it reads u + c₂·(u − mid)², u its linear reading (Eq. 1, the
  /// zero adjustment and the traverse's zero shift included); 0 = linear.
  double nonlinearity_c2_per_um = 0.0;
  double nonlinearity_mid_um = 0.0;
  /// The sensor's hysteresis h (µm, >= 0): it reads r − h·sign(dr/dt); 0 = none.
  double hysteresis_um = 0.0;
};

struct SequenceSimOptions {
  double sigma_um = 0.1;  ///< noise of every reading
  std::uint64_t seed = 1;
  SequenceEffects effects;
};

struct SequenceSimData {
  Eigen::MatrixXd m_um;        ///< P × T readings (column k = traverse k) with effects and noise
  Eigen::MatrixXd m_clean_um;  ///< the same truth and noise without the effects
  Eigen::MatrixXd t_s;         ///< P × T reading times
  Eigen::VectorXd x_mm, S_um, gamma_rad;  ///< P; S of the first traverse
  Eigen::VectorXd f_um;                   ///< N
};

/// Throws std::invalid_argument for an invalid configuration or sequence, or σ < 0.
SequenceSimData simulate_four_sensor_sequence(const FourSensorConfig& cfg,
                                              const SlidewayTruth& truth, const ScanSequence& seq,
                                              const SequenceSimOptions& opts = {});

}  // namespace errsep::core

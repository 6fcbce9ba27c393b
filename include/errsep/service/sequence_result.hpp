#pragma once
// A recorded scan sequence's refined fit (core/sequence_refine.hpp) as a result folder shows it:
// motion.csv, reference.csv, residuals.csv and summary.txt in the single separation's form, with
// the metadata that say what it is (estimator scan_sequence_fit, no prior, its own uncertainty
// model, the plan, the effects applied and the findings) and the ISO 230-1 straightness with U
// from the fit's covariance.  The scan's result folder (service/four_sensor_pipeline.hpp) and
// its refine/ (service/refine_run.hpp) write the same result from the same fit.
#include <Eigen/Core>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/scan_sequence.hpp"
#include "errsep/core/sequence_refine.hpp"
#include "errsep/io/four_sensor_result_csv.hpp"

namespace errsep::service {

/// True when a recorded sequence's fit is the result rather than the separation of m1..m4: more
/// than one traverse of a configuration, or a plan other than single.
bool sequence_is_the_result(const core::ScanSequence& seq);

/// The fit of `sr` in the separation's form: S, γ, f and their uncertainties in the fit's gauge
/// (the default separation's: f's ends at 0, f without bow), the residuals of each
/// configuration's first traverse, λ = 0.  `single`: the separation of m1..m4 (its geometry and
/// grids are taken).
core::FourSensorResult sequence_as_result(const core::FourSensorResult& single,
                                          const core::ScanSequence& seq,
                                          const core::SequenceRefineResult& sr);

/// Above this ratio of γ's u in the fit's gauge (motion.csv's u_gamma_urad) to its u about γ's
/// best-fit constant and line (RMS of each), γ's level is said not to be determined by the plan
/// (gamma_level_determined_by_data: false and a summary line).  Measured (reversed closing, σ
/// 0.1 µm, seed 10; tests/service/refine_run.cpp): 1.1 without fitted effects, 1.3 with a
/// linear drift, 35 with a warm-up of every configuration at τ = 40 s (about 770 at the τ the
/// refine fitted in errsep-refine-sweep's thermal_all cell, same seed).
inline constexpr double kGammaLevelUndeterminedRatio = 10.0;

/// Adds to `info` what the files of that result say about it: summary.txt's first line, every
/// traverse's residual, estimator and uncertainty model, scan_plan and separation metadata,
/// summary notes with the findings, γ's u about its constant and line (and whether the plan
/// determines its level), and the straightness figures with U over `x_mm`.
void describe_sequence_result(const core::FourSensorConfig& cfg, const core::ScanSequence& seq,
                              const core::SequenceRefineResult& sr, const Eigen::VectorXd& x_mm,
                              io::ResultWriteInfo& info);

}  // namespace errsep::service

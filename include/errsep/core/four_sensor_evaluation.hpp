#pragma once
// ISO 230-1 straightness of a four-sensor separation with the uncertainty of the separation
// itself: U from the covariance of the points that fix the reference line and the zone (the
// posterior's, FourSensorResult::covariance), the bias that noise gives max − min removed by
// Monte Carlo over posterior draws (iso230.hpp, estimate_straightness).  A result without a
// covariance (the paper's system) falls back to the per-point bound of evaluate_straightness.
#include "errsep/core/four_sensor.hpp"
#include "errsep/core/iso230.hpp"

namespace errsep::core {

/// Straightness of r.S_um about `reference`.  `draws` Monte Carlo draws for the bias (>= 20).
StraightnessEstimate four_sensor_straightness(const FourSensorResult& r, ReferenceLine reference,
                                              int draws = 100, const EvaluationOptions& opts = {});

}  // namespace errsep::core

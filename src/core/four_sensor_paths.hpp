#pragma once
// The estimators behind separate_four_sensor (four_sensor.hpp), one per Estimator.  Private to
// core: callers use separate_four_sensor, which validates the options and dispatches.
#include <Eigen/Core>

#include "errsep/core/four_sensor.hpp"

namespace errsep::core {

/// Estimator::posterior (four_sensor_posterior.cpp).  `known_sigma_um` > 0 is used instead of
/// the σ̂ of the redundant readings (predict_four_sensor_uncertainty: no data, a stated σ).
FourSensorResult separate_posterior(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                                    const FourSensorOptions& opts, double known_sigma_um = 0.0);

}  // namespace errsep::core

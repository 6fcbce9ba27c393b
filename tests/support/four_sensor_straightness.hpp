#pragma once
// The ISO 230-1 straightness of a four-sensor result as errsep states it: the figure of the
// estimated S with its Monte Carlo bias correction and U from the separation's covariance
// (core::estimate_straightness with the result's FourSensorCovariance).  Needs a result of the
// posterior estimator computed with uncertainties (result.covariance set).
#include <Eigen/Core>
#include <vector>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/iso230.hpp"

namespace errsep::test {

inline core::StraightnessEstimate four_sensor_straightness(const core::FourSensorResult& r,
                                                           core::ReferenceLine reference) {
  const std::vector<double> x(r.x_mm.data(), r.x_mm.data() + r.x_mm.size());
  const std::vector<double> s(r.S_um.data(), r.S_um.data() + r.S_um.size());
  auto cov = r.covariance;
  return core::estimate_straightness(
      x, s,
      [cov](const std::vector<double>& c) {
        return cov->variance(
            Eigen::Map<const Eigen::VectorXd>(c.data(), static_cast<Eigen::Index>(c.size())), {},
            {});
      },
      [cov](std::uint64_t seed, std::vector<double>& dev) {
        Eigen::VectorXd dS, dg;
        cov->sample(seed, dS, dg);
        dev.assign(dS.data(), dS.data() + dS.size());
      },
      reference);
}

}  // namespace errsep::test

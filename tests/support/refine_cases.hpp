#pragma once
// Simulated four-sensor scans with effects the model does not declare, for the refine tests:
// Zhao 2019 Example 1 geometry and truth, an effect injected into the readings, noise.
#include <Eigen/Core>
#include <cmath>
#include <functional>
#include <numbers>

#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/core/refine.hpp"
#include "errsep/core/residual_analysis.hpp"

namespace errsep::test {

struct RefineCase {
  core::FourSensorConfig cfg;
  core::FourSensorSimData sim;
  Eigen::MatrixXd t_s;  ///< scan-order times (as the refine loop assumes when none are given)
  core::RefineTruth truth;
};

/// Example 1 (N = 69, s = (1, 1, 5), Δx = 5 mm); `modify` may set PE1/PE2 in the simulation
/// options; `post` may change the readings afterwards (gain, drift, bumps); example2_k > 0 uses
/// Example 2's reference surface (Eq. 24) instead.
inline RefineCase make_refine_case(
    double sigma_um, std::uint64_t seed,
    const std::function<void(core::FourSensorSimOptions&)>& modify = {},
    const std::function<void(Eigen::MatrixXd& m, const Eigen::MatrixXd& t_s)>& post = {},
    int example2_k = 0) {
  RefineCase c;
  core::FourSensorSimOptions so;
  so.sigma_um = sigma_um;
  so.seed = seed;
  if (modify) modify(so);
  const core::SlidewayTruth truth =
      example2_k > 0 ? core::zhao2019_example2(c.cfg, example2_k) : core::zhao2019_example1(c.cfg);
  c.sim = core::simulate_four_sensor(c.cfg, truth, so);
  c.t_s = core::scan_order_times_s(c.cfg);
  if (post) post(c.sim.m_um, c.t_s);
  c.truth.f_um = c.sim.f_um;
  c.truth.S_um = c.sim.S_um;
  c.truth.gamma_rad = c.sim.gamma_rad;
  return c;
}

}  // namespace errsep::test

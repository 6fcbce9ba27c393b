#pragma once
// Simulation platform for the four-sensor method (Zhao et al. 2019, section 3): sensor outputs of
// Eq. (1) from a given truth, with Gaussian noise σ, the sensor positioning error PE1 (actual
// D2, D3, D4 differ from nominal) and the slideway positioning error PE2 (Eq. 20), seeded.
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <optional>

#include "errsep/core/four_sensor_config.hpp"
#include "errsep/core/four_sensor_model.hpp"

namespace errsep::core {

struct FourSensorSimOptions {
  double sigma_um = 0.0;  ///< standard deviation of the Gaussian noise added to every reading
  /// PE1: actual spacings D2, D3, D4 in mm (nominal s_i·Δx when empty).
  std::optional<std::array<double, 3>> actual_spacing_mm;
  /// PE2: slideway positioning error in µm as a function of the nominal position x (mm): the
  /// slide is really at x + PE2(x)/1000 when commanded to x.  Empty = none.
  ProfileFn positioning_error_um;
  std::uint64_t seed = 1;  ///< the same seed gives the same readings
};

struct FourSensorSimData {
  Eigen::MatrixXd m_um;       ///< P × 4 sensor outputs, row n = slide position x_n
  Eigen::VectorXd x_mm;       ///< P slide positions x_n = n·Δx
  Eigen::VectorXd S_um;       ///< truth S(x_n), P
  Eigen::VectorXd gamma_rad;  ///< truth γ(x_n), P
  Eigen::VectorXd f_x_mm;     ///< N reference-surface sample positions
  Eigen::VectorXd f_um;       ///< truth f(x_0..x_{N-1}), N
};

/// Samples the model of Eq. (1) on the configuration's grid.  Throws std::invalid_argument if the
/// configuration is not valid.
FourSensorSimData simulate_four_sensor(const FourSensorConfig& cfg, const SlidewayTruth& truth,
                                       const FourSensorSimOptions& opts = {});

/// The paper's test functions.  Example 1: S of Eq. (21), γ of Eq. (22) (degrees in the paper,
/// returned in rad), f of Eq. (23).  L is the travel, L0 the reference length of `cfg`.
SlidewayTruth zhao2019_example1(const FourSensorConfig& cfg);
/// Example 2: as Example 1 but f of Eq. (24) with harmonic order k.
SlidewayTruth zhao2019_example2(const FourSensorConfig& cfg, int k);
/// PE1 of section 3: D2, D3, D4 = 5.012, 4.985, 25.02 mm.
std::array<double, 3> zhao2019_pe1_spacing_mm();
/// PE2 of Eq. (20) in µm, for travel L in mm.
ProfileFn zhao2019_pe2_um(double travel_mm);

}  // namespace errsep::core

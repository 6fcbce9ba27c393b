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

/// Where the simulated noise enters.
enum class NoiseModel {
  /// Physics: each sensor reading m_i(x_n) of Eq. (1) carries its own Gaussian noise σ, so the
  /// combined outputs g = C·m of Eq. (9) carry correlated noise of covariance σ²·C·Cᵀ per position.
  sensor_outputs,
  /// Each combined output g_r(x_n) carries its own independent noise σ (and m_1 … m_4, used for
  /// S and γ in Eqs. 18–19, their own), as when the combinations are formed in the instrument or
  /// a simulation adds the noise to b₀ (Eq. 6) directly, as Tikhonov test scripts do.
  ///
  /// Why it is here: the figures of Zhao 2019, section 3, come out under this model and not under
  /// the one its text states ("added in m_i(x_n)").  With σ on m, no unbiased estimate reaches
  /// them (the Gauss–Markov floor of ΔS_max over 20 runs is ~2.3 µm at σ = 0.1 µm, the paper
  /// 1.1) and identity-Tikhonov trades it only for bias; with σ on g the minimum-variance
  /// separation gives ΔS_max 0.85/1.70/2.55 µm, ΔS^a 0.13/0.26/0.39 µm, Δγ 1.3/2.6/4.0e-3°,
  /// Δγ^a 2.3/4.7/7.0e-4° at σ = 0.1/0.2/0.3 (paper 1.1/1.6/2.3, 0.15/0.26/0.30,
  /// 1.8/3.2/3.9e-3, 2.5/6.5/7.2e-4) and ΔS_max ≈ 1.7 µm for every k of Example 2 (paper < 2.6):
  /// all eight figures and their ratio ΔS_max/ΔS^a ≈ 7 (17 with σ on m, where the error
  /// concentrates at the far end).  See tests/core/four_sensor_zhao2019.cpp.
  combined_outputs,
};

struct FourSensorSimOptions {
  double sigma_um = 0.0;  ///< standard deviation of the Gaussian noise (see noise_model)
  NoiseModel noise_model = NoiseModel::sensor_outputs;
  /// PE1: actual spacings D2, D3, D4 in mm (nominal s_i·Δx when empty).
  std::optional<std::array<double, 3>> actual_spacing_mm;
  /// PE2: slideway positioning error in µm as a function of the nominal position x (mm): the
  /// slide is really at x + PE2(x)/1000 when commanded to x.  Empty = none.
  ProfileFn positioning_error_um;
  std::uint64_t seed = 1;  ///< the same seed gives the same readings
};

struct FourSensorSimData {
  Eigen::MatrixXd m_um;  ///< P × 4 sensor outputs, row n = slide position x_n
  /// P × 4 combined outputs g(x_n) (Eq. 9): C·m for NoiseModel::sensor_outputs, C·m_noise-free
  /// plus independent noise for NoiseModel::combined_outputs (feed separate_four_sensor_combined).
  Eigen::MatrixXd g_um;
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
/// Random smooth profiles for tests on cases nobody designed for: each of S, γ and f is a sum of
/// a random number of sine harmonics with random periods (counted over the travel L for S and γ,
/// over the reference length L0 for f), amplitudes and phases.  f is then put in the gauge the
/// separation reports (f(x_0) = f(x_{N−1}) = 0, no bow: a + b·x + c·x² added), so that the truth
/// and the estimate mean the same S; e = (0, e2, e3, 0) with e2, e3 ~ N(0, e_sd).
struct RandomTruthOptions {
  int min_harmonics = 2, max_harmonics = 4;
  double S_periods_min = 0.5, S_periods_max = 8.0;  ///< periods over L
  double S_amplitude_min_um = 0.5, S_amplitude_max_um = 6.0;
  double gamma_periods_min = 0.5, gamma_periods_max = 6.0;
  double gamma_amplitude_min_urad = 20.0, gamma_amplitude_max_urad = 200.0;
  double f_periods_min = 1.0, f_periods_max = 15.0;  ///< periods over L0
  double f_amplitude_min_um = 0.3, f_amplitude_max_um = 4.0;
  double e_sd_um = 0.5;
};
SlidewayTruth random_smooth_truth(const FourSensorConfig& cfg, std::uint64_t seed,
                                  const RandomTruthOptions& o = {});

/// PE1 of section 3, the positioning error of the sensor: D2, D3, D4 = 5.012, 4.985, 25.02 mm
/// where the nominal spacings are 5, 5, 25 mm, i.e. the sensor stage misses each position by
/// +12, -15, +20 µm.  For another geometry the same misses are added to its nominal spacings
/// s_i·Δx: a positioning error is a length, not a fraction of the spacing (the default geometry
/// gives the paper's figures).
std::array<double, 3> zhao2019_pe1_spacing_mm(const FourSensorConfig& cfg = {});
/// PE2 of Eq. (20) in µm, for travel L in mm.
ProfileFn zhao2019_pe2_um(double travel_mm);

}  // namespace errsep::core

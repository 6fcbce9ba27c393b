#include "errsep/core/four_sensor_simulation.hpp"

#include "errsep/core/four_sensor_system.hpp"

#include <Eigen/Dense>
#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace errsep::core {

FourSensorSimData simulate_four_sensor(const FourSensorConfig& cfg, const SlidewayTruth& truth,
                                       const FourSensorSimOptions& opts) {
  std::string why;
  if (!cfg.is_valid(&why)) throw std::invalid_argument("invalid configuration: " + why);
  if (!truth.f_um || !truth.S_um || !truth.gamma_rad)
    throw std::invalid_argument("simulation truth needs f, S and gamma functions");
  const int N = cfg.N, P = cfg.positions();
  std::array<double, 4> O = cfg.offsets_mm();
  if (opts.actual_spacing_mm) {  // PE1: the sensor is really at these spacings
    const auto& D = *opts.actual_spacing_mm;
    O = {0.0, D[0], D[0] + D[1], D[0] + D[1] + D[2]};
  }
  std::mt19937_64 rng(opts.seed);
  std::normal_distribution<double> noise(0.0, 1.0);

  const bool on_g = opts.noise_model == NoiseModel::combined_outputs;
  const Eigen::Matrix4d C = combination_matrix(cfg);
  FourSensorSimData d;
  d.m_um.resize(P, 4);
  d.g_um.resize(P, 4);
  d.x_mm.resize(P);
  d.S_um.resize(P);
  d.gamma_rad.resize(P);
  for (int n = 0; n < P; ++n) {
    const double x = n * cfg.dx_mm;
    d.x_mm(n) = x;
    d.S_um(n) = truth.S_um(x);
    d.gamma_rad(n) = truth.gamma_rad(x);
    Eigen::Vector4d clean;
    for (int i = 0; i < 4; ++i) {
      // PE2 (Eq. 20): the slide stands at x + PE2(x) when commanded to x; every quantity that moves
      // with the slide is sampled there.
      const double xa = opts.positioning_error_um ? x + 1e-3 * opts.positioning_error_um(x) : x;
      clean(i) = four_sensor_reading_um(truth, xa, O[i]) + truth.e_um[static_cast<size_t>(i)];
      d.m_um(n, i) = clean(i) + opts.sigma_um * noise(rng);  // Eq. (1) plus noise
    }
    if (on_g) {
      const Eigen::Vector4d g = C * clean;
      for (int r = 0; r < 4; ++r)
        d.g_um(n, r) = g(r) + opts.sigma_um * noise(rng);
    } else {
      d.g_um.row(n) = (C * d.m_um.row(n).transpose()).transpose();
    }
  }
  d.f_x_mm.resize(N);
  d.f_um.resize(N);
  for (int n = 0; n < N; ++n) {
    d.f_x_mm(n) = n * cfg.dx_mm;
    d.f_um(n) = truth.f_um(n * cfg.dx_mm);
  }
  return d;
}

namespace {
constexpr double pi = std::numbers::pi;
}

SlidewayTruth zhao2019_example1(const FourSensorConfig& cfg) {
  const double L = cfg.travel_mm(), L0 = cfg.reference_length_mm();
  SlidewayTruth t;
  t.S_um = [L](double x) {  // Eq. (21), µm
    return 8.075 * std::sin(4 * pi / L * x) + 5.7 * std::sin(6 * pi / L * x + 5.0 / 18 * pi) -
           1.9 * std::sin(14 * pi / L * x + 0.5 * pi);
  };
  t.gamma_rad = [L](double x) {  // Eq. (22), printed in degrees
    return kRadPerDeg *
           (0.008 * std::sin(2 * pi / L * x + pi / 3) - 0.014 * std::sin(4 * pi / L * x + pi / 4) +
            0.005 * std::sin(10 * pi / L * x + 7.0 / 12 * pi));
  };
  t.f_um = [L0](double x) { return 5.0 * std::sin(10 * pi / L0 * x); };  // Eq. (23)
  // The paper does not give its zero-adjustment values.  These follow e_i = b·O_i + d·O_i³ (O in
  // samples 0, 1, 2, 7): a sensor stage whose error has no quadratic part, the assumption of the
  // default curvature gauge (a quadratic part is not identifiable; see four_sensor_system.hpp).
  t.e_um = {0.0, 0.49, 0.92, 0.07};
  return t;
}

SlidewayTruth zhao2019_example2(const FourSensorConfig& cfg, int k) {
  SlidewayTruth t = zhao2019_example1(cfg);
  const double L0 = cfg.reference_length_mm();
  t.f_um = [L0, k](double x) {  // Eq. (24)
    return 5.0 * std::sin(k * 2 * pi / L0 * x) + 5.0 * std::sin(20 * pi / L0 * x);
  };
  return t;
}

std::array<double, 3> zhao2019_pe1_spacing_mm(const FourSensorConfig& cfg) {
  // Section 3: Δx = 5 mm, s = (1, 1, 5) nominal 5, 5, 25 mm; actual 5.012, 4.985, 25.02 mm.
  constexpr std::array<double, 3> miss_mm = {0.012, -0.015, 0.020};
  return {cfg.s2 * cfg.dx_mm + miss_mm[0], cfg.s3 * cfg.dx_mm + miss_mm[1],
          cfg.s4 * cfg.dx_mm + miss_mm[2]};
}

ProfileFn zhao2019_pe2_um(double L) {
  return [L](double x) {  // Eq. (20), µm
    return -10.0 * std::sin(2 * pi / L * x + pi / 12) - 3.0 * std::sin(6 * pi / L * x + 0.5 * pi) +
           4.5 * std::sin(2 * pi / L * x + 5.0 / 6 * pi);
  };
}

SlidewayTruth random_smooth_truth(const FourSensorConfig& cfg, std::uint64_t seed,
                                  const RandomTruthOptions& o) {
  std::string why;
  if (!cfg.is_valid(&why)) throw std::invalid_argument("invalid configuration: " + why);
  std::mt19937_64 rng(seed);
  auto uni = [&](double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); };
  struct Harmonic {
    double amplitude, wavenumber, phase;  // a·sin(k·x + φ)
  };
  auto draw = [&](double length, double pmin, double pmax, double amin, double amax) {
    std::vector<Harmonic> h(static_cast<std::size_t>(
        std::uniform_int_distribution<int>(o.min_harmonics, o.max_harmonics)(rng)));
    for (auto& c : h)
      c = {uni(amin, amax), 2 * pi * uni(pmin, pmax) / length, uni(0.0, 2 * pi)};
    return h;
  };
  auto eval = [](const std::vector<Harmonic>& h, double x) {
    double v = 0.0;
    for (const auto& c : h)
      v += c.amplitude * std::sin(c.wavenumber * x + c.phase);
    return v;
  };
  const double L = cfg.travel_mm(), L0 = cfg.reference_length_mm();
  const auto hS =
      draw(L, o.S_periods_min, o.S_periods_max, o.S_amplitude_min_um, o.S_amplitude_max_um);
  const auto hg = draw(L, o.gamma_periods_min, o.gamma_periods_max,
                       o.gamma_amplitude_min_urad * 1e-6, o.gamma_amplitude_max_urad * 1e-6);
  const auto hf =
      draw(L0, o.f_periods_min, o.f_periods_max, o.f_amplitude_min_um, o.f_amplitude_max_um);
  // a + b·t + c·t² (t = x/L0) that puts f in the gauge on the sample grid.
  const int N = cfg.N;
  Eigen::Matrix3d G = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  for (int n = 0; n < N; ++n) {
    const double t = static_cast<double>(n) / (N - 1), bow = t * (1 - t);
    const double fv = eval(hf, n * cfg.dx_mm);
    if (n == 0 || n == N - 1) {
      const int r = n == 0 ? 0 : 1;
      G.row(r) << 1.0, t, t * t;
      rhs(r) = -fv;
    }
    G.row(2) += bow * Eigen::RowVector3d(1.0, t, t * t);
    rhs(2) -= bow * fv;
  }
  const Eigen::Vector3d abc = G.partialPivLu().solve(rhs);
  SlidewayTruth t;
  t.S_um = [hS, eval](double x) { return eval(hS, x); };
  t.gamma_rad = [hg, eval](double x) { return eval(hg, x); };
  t.f_um = [hf, eval, abc, L0](double x) {
    const double u = x / L0;
    return eval(hf, x) + abc(0) + abc(1) * u + abc(2) * u * u;
  };
  std::normal_distribution<double> e(0.0, o.e_sd_um);
  t.e_um = {0.0, e(rng), e(rng), 0.0};
  return t;
}

}  // namespace errsep::core

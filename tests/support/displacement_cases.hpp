#pragma once
// Random two-axis stages for the displacement method's tests (Haramiishi 2024 model, as
// simulate_two_axis reads it): every seed draws new profiles (several harmonics with random
// periods, phases and amplitudes, plus a slope) for the workpiece, the four reference tracks, the
// straightness of both tables and their roll and pitch.  Not designed for any one feature.
#include <Eigen/Core>
#include <cmath>
#include <random>
#include <vector>

#include "errsep/core/displacement_simulation.hpp"

namespace errsep::test {

struct Harmonic {
  double amplitude, period_mm, phase;
};

/// `count` harmonics of random amplitude in [0.2, 1]·amp (then scaled so that their amplitudes
/// sum to amp), period in [L/3, 3L] and phase in [0, 2π).
inline std::vector<Harmonic> random_harmonics(std::mt19937_64& rng, int count, double amp,
                                              double length_mm) {
  std::uniform_real_distribution<double> a(0.2, 1.0), per(length_mm / 3, 3 * length_mm),
      ph(0, 2 * M_PI);
  std::vector<Harmonic> h;
  double sum = 0;
  for (int k = 0; k < count; ++k) {
    h.push_back({a(rng), per(rng), ph(rng)});
    sum += h.back().amplitude;
  }
  for (auto& x : h)
    x.amplitude *= amp / sum;
  return h;
}

inline double eval(const std::vector<Harmonic>& h, double s_mm) {
  double v = 0;
  for (const auto& x : h)
    v += x.amplitude * std::sin(2 * M_PI * s_mm / x.period_mm + x.phase);
  return v;
}

/// A random 1-D profile: harmonics of total amplitude amp plus a slope in ±slope µm/mm.
inline core::AxisFn random_profile(std::mt19937_64& rng, double amp, double slope,
                                   double length_mm) {
  const auto h = random_harmonics(rng, 3, amp, length_mm);
  const double s = std::uniform_real_distribution<double>(-slope, slope)(rng);
  return [h, s](double x) { return eval(h, x) + s * x; };
}

/// A random function on the grid: harmonics in x, in y and in x + y.
inline core::GridFn random_surface(std::mt19937_64& rng, double amp, double length_mm) {
  const auto hx = random_harmonics(rng, 2, amp / 3, length_mm);
  const auto hy = random_harmonics(rng, 2, amp / 3, length_mm);
  const auto hxy = random_harmonics(rng, 2, amp / 3, length_mm);
  return [hx, hy, hxy](double x, double y) { return eval(hx, x) + eval(hy, y) + eval(hxy, x + y); };
}

/// A stage of the paper's size (120 mm) with w of ~10 µm, reference pieces of ~2 µm and
/// straightness of ~5 µm; roll and pitch vary over the grid with peak-to-peak about
/// rotation_urad (0: none).
inline core::TwoAxisTruth random_two_axis_truth(std::uint64_t seed, double rotation_urad,
                                                double length_mm = 120.0) {
  std::mt19937_64 rng(seed * 7919 + 17);
  core::TwoAxisTruth t;
  t.w_um = random_surface(rng, 10.0, length_mm);
  t.r1x_um = random_profile(rng, 2.0, 0.03, length_mm);
  t.r2x_um = random_profile(rng, 2.0, 0.03, length_mm);
  t.r3y_um = random_profile(rng, 2.0, 0.03, length_mm);
  t.r4y_um = random_profile(rng, 2.0, 0.03, length_mm);
  const auto ezx = random_surface(rng, 5.0, length_mm), ezy = random_surface(rng, 5.0, length_mm);
  t.ez_x_um = [ezx](double x, double y) { return ezx(x, y) - 0.05 * x; };
  t.ez_y_um = [ezy](double x, double y) { return ezy(x, y) - 0.05 * y; };
  // Amplitudes sum to half the peak-to-peak: the roll stays within ±rotation/2.
  const auto roll = random_surface(rng, 1e-6 * rotation_urad / 2, length_mm);
  const auto pitch = random_surface(rng, 1e-6 * rotation_urad / 2, length_mm);
  t.roll_x_rad = roll;
  t.pitch_y_rad = pitch;
  return t;
}

/// The truth of every estimated quantity in the joint estimate's gauge (r_k(first sample) = 0):
/// r_k − r_k(x_0), m_k + r_k(x_0), and m_w, w with the constant Σ c_k·r_k(x_0) that follows.
struct GaugedTruth {
  Eigen::MatrixXd m[4], w, m_w;
  Eigen::VectorXd r[4];  ///< r1, r2 along x (nx), r3, r4 along y (ny)
};

inline GaugedTruth gauged_truth(const core::TwoAxisTruth& t, const core::TwoAxisSimData& sim,
                                const core::TwoAxisGeometry& g, bool rotation_corrected) {
  const auto& x = sim.scan.x_mm;
  const auto& y = sim.scan.y_mm;
  const Eigen::Index nx = x.size(), ny = y.size();
  const double r0[4] = {t.r1x_um(x(0)), t.r2x_um(x(0)), t.r3y_um(y(0)), t.r4y_um(y(0))};
  GaugedTruth out;
  for (auto& m : out.m)
    m.resize(nx, ny);
  out.r[0].resize(nx);
  out.r[1].resize(nx);
  out.r[2].resize(ny);
  out.r[3].resize(ny);
  for (Eigen::Index i = 0; i < nx; ++i) {
    out.r[0](i) = t.r1x_um(x(i)) - r0[0];
    out.r[1](i) = t.r2x_um(x(i)) - r0[1];
  }
  for (Eigen::Index j = 0; j < ny; ++j) {
    out.r[2](j) = t.r3y_um(y(j)) - r0[2];
    out.r[3](j) = t.r4y_um(y(j)) - r0[3];
  }
  const double kx = g.l_xw_mm / g.l_xs_mm;
  out.w.resize(nx, ny);
  out.m_w.resize(nx, ny);
  for (Eigen::Index j = 0; j < ny; ++j)
    for (Eigen::Index i = 0; i < nx; ++i) {
      const double ezx = t.ez_x_um(x(i), y(j)), ezy = t.ez_y_um(x(i), y(j));
      out.m[1](i, j) = ezx + r0[1];
      out.m[0](i, j) = ezx + 1000.0 * t.roll_x_rad(x(i), y(j)) * g.l_xs_mm + r0[0];
      out.m[3](i, j) = ezy + r0[3];
      out.m[2](i, j) = ezy + 1000.0 * t.pitch_y_rad(x(i), y(j)) * g.l_ys_mm + r0[2];
      const double ky = (g.l_yw_mm + g.l_yw_per_x * (x(i) - x(0))) / g.l_ys_mm;
      const double c = rotation_corrected
                           ? kx * r0[0] + (1 - kx) * r0[1] + ky * r0[2] + (1 - ky) * r0[3]
                           : r0[1] + r0[3];
      out.m_w(i, j) = sim.m_w_um(i, j) + c;
      out.w(i, j) = sim.w_um(i, j) - c;
    }
  return out;
}

}  // namespace errsep::test

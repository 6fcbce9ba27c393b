#include "errsep/core/undeclared_effect_simulation.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <stdexcept>

#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/core/residual_analysis.hpp"

namespace errsep::core {

namespace {
constexpr double kPi = std::numbers::pi;

struct Name {
  UndeclaredEffect e;
  const char* name;
  const char* library;
};
constexpr Name kNames[] = {
    {UndeclaredEffect::none, "none", ""},
    {UndeclaredEffect::pe1, "pe1", "pe1"},
    {UndeclaredEffect::gain, "gain", "gain"},
    {UndeclaredEffect::drift_one, "drift_one", "drift"},
    {UndeclaredEffect::drift_all, "drift_all", "drift"},
    {UndeclaredEffect::pe2, "pe2", "pe2"},
    {UndeclaredEffect::periodic, "periodic", "periodic"},
    {UndeclaredEffect::thermal_one, "thermal_one", "thermal"},
    {UndeclaredEffect::thermal_all, "thermal_all", "thermal"},
    {UndeclaredEffect::traverse, "traverse", "traverse"},
    {UndeclaredEffect::nonlinearity, "nonlinearity", ""},
    {UndeclaredEffect::bump, "bump", ""},
    {UndeclaredEffect::hysteresis, "hysteresis", ""},
};

// Legendre P_k(u), k = 0..3.
double legendre(int k, double u) {
  switch (k) {
    case 0:
      return 1.0;
    case 1:
      return u;
    case 2:
      return 0.5 * (3.0 * u * u - 1.0);
    default:
      return 0.5 * (5.0 * u * u * u - 3.0 * u);
  }
}
}  // namespace

const char* to_string(UndeclaredEffect e) {
  for (const auto& n : kNames)
    if (n.e == e) return n.name;
  return "unknown";
}

std::optional<UndeclaredEffect> undeclared_effect_from_string(std::string_view s) {
  for (const auto& n : kNames)
    if (s == n.name) return n.e;
  return std::nullopt;
}

std::vector<UndeclaredEffect> all_undeclared_effects() {
  std::vector<UndeclaredEffect> v;
  for (const auto& n : kNames)
    v.push_back(n.e);
  return v;
}

std::string library_effect_name(UndeclaredEffect e) {
  for (const auto& n : kNames)
    if (n.e == e) return n.library;
  return {};
}

bool in_refine_library(UndeclaredEffect e, bool plan_is_single) {
  if (plan_is_single) return !library_effect_name(e).empty();
  switch (e) {
    case UndeclaredEffect::drift_one:
    case UndeclaredEffect::drift_all:
    case UndeclaredEffect::thermal_one:
    case UndeclaredEffect::thermal_all:
    case UndeclaredEffect::traverse:
    case UndeclaredEffect::hysteresis:
      return true;
    default:
      return false;
  }
}

RandomTruthOptions UndeclaredCaseOptions::wavy_reference() {
  RandomTruthOptions t;
  t.f_amplitude_min_um = 2.0;
  t.f_amplitude_max_um = 5.0;
  t.f_periods_min = 3.0;
  t.f_periods_max = 12.0;
  return t;
}

bool UndeclaredCaseOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  std::string w;
  if (!cfg.is_valid(&w)) return fail("cfg: " + w);
  if (!(sigma_um >= 0)) return fail("sigma_um = " + std::to_string(sigma_um) + ": must be >= 0");
  if (!(speed_mm_per_s > 0))
    return fail("speed_mm_per_s = " + std::to_string(speed_mm_per_s) + ": must be > 0");
  if (!(size >= 0)) return fail("size = " + std::to_string(size) + ": must be >= 0");
  return true;
}

UndeclaredCase simulate_undeclared(UndeclaredEffect effect, const UndeclaredCaseOptions& o) {
  std::string why;
  if (!o.is_valid(&why)) throw std::invalid_argument("undeclared case options: " + why);
  const FourSensorConfig& cfg = o.cfg;
  const int P = cfg.positions();
  const double L = cfg.travel_mm();
  const SlidewayTruth truth = random_smooth_truth(cfg, o.seed, o.truth);
  UndeclaredEffectDraws draw(o.seed);
  const double k = o.size;

  FourSensorSimOptions so;
  so.sigma_um = o.sigma_um;
  so.seed = undeclared_noise_seed(o.seed);
  UndeclaredCase c;
  c.cfg = cfg;
  c.t_s = scan_order_times_s(cfg, o.speed_mm_per_s);
  const FourSensorSimData clean = simulate_four_sensor(cfg, truth, so);
  c.m_clean_um = clean.m_um;
  c.f_um = clean.f_um;
  c.S_um = clean.S_um;
  c.gamma_rad = clean.gamma_rad;
  c.m_um = clean.m_um;
  char buf[300];
  switch (effect) {
    case UndeclaredEffect::none:
      c.description = "none";
      break;
    case UndeclaredEffect::pe1: {
      const auto O = cfg.offsets_mm();
      std::array<double, 3> D = {O[1] - O[0], O[2] - O[1], O[3] - O[2]};
      const int skip = draw.pick(0, 2);  // two of the three spacings are off
      std::array<double, 3> dD = {0, 0, 0};
      for (int j = 0; j < 3; ++j)
        if (j != skip) dD[static_cast<std::size_t>(j)] = k * draw.sign() * draw.uni(0.4, 0.9);
      for (int j = 0; j < 3; ++j)
        D[static_cast<std::size_t>(j)] += dD[static_cast<std::size_t>(j)];
      so.actual_spacing_mm = D;
      c.m_um = simulate_four_sensor(cfg, truth, so).m_um;
      std::snprintf(buf, sizeof buf, "pe1: spacings off by %.3g, %.3g, %.3g mm", dD[0], dD[1],
                    dD[2]);
      c.description = buf;
      break;
    }
    case UndeclaredEffect::gain: {
      const int i = draw.pick(1, 3);
      const double g = k * draw.sign() * draw.uni(0.03, 0.06);
      c.m_um.col(i) *= 1.0 + g;
      std::snprintf(buf, sizeof buf, "gain: configuration %d reads %+.3g %%", i + 1, 100 * g);
      c.description = buf;
      break;
    }
    case UndeclaredEffect::drift_one:
    case UndeclaredEffect::drift_all: {
      const bool one = effect == UndeclaredEffect::drift_one;
      const int which = draw.pick(0, 3);
      std::array<double, 4> a = {0, 0, 0, 0};
      for (int i = 0; i < 4; ++i)
        if (!one || i == which)
          a[static_cast<std::size_t>(i)] = k * draw.sign() * draw.uni(0.01, 0.03);
      for (int i = 0; i < 4; ++i)
        c.m_um.col(i) += a[static_cast<std::size_t>(i)] * c.t_s.col(i);
      std::snprintf(buf, sizeof buf, "linear drift %.3g, %.3g, %.3g, %.3g um/s", a[0], a[1], a[2],
                    a[3]);
      c.description = buf;
      break;
    }
    case UndeclaredEffect::thermal_one:
    case UndeclaredEffect::thermal_all: {
      const bool one = effect == UndeclaredEffect::thermal_one;
      const int which = draw.pick(0, 3);
      const double tau = draw.uni(20.0, 80.0);
      std::array<double, 4> a = {0, 0, 0, 0};
      for (int i = 0; i < 4; ++i)
        if (!one || i == which)
          a[static_cast<std::size_t>(i)] = k * draw.sign() * draw.uni(2.0, 5.0);
      const double t0 = c.t_s.minCoeff();
      for (int i = 0; i < 4; ++i)
        c.m_um.col(i) += a[static_cast<std::size_t>(i)] *
                         (1.0 - (-(c.t_s.col(i).array() - t0) / tau).exp()).matrix();
      std::snprintf(buf, sizeof buf, "thermal drift %.3g, %.3g, %.3g, %.3g um, tau %.3g s", a[0],
                    a[1], a[2], a[3], tau);
      c.description = buf;
      break;
    }
    case UndeclaredEffect::pe2:
    case UndeclaredEffect::periodic: {
      if (effect == UndeclaredEffect::pe2) {
        const std::array<double, 3> cc = {k * draw.sign() * draw.uni(300.0, 800.0),
                                          k * draw.sign() * draw.uni(300.0, 800.0),
                                          k * draw.sign() * draw.uni(300.0, 800.0)};
        so.positioning_error_um = [cc, L](double x) {
          const double u = 2.0 * x / L - 1.0;
          return cc[0] * legendre(1, u) + cc[1] * legendre(2, u) + cc[2] * legendre(3, u);
        };
        std::snprintf(buf, sizeof buf, "pe2: Legendre P1..P3 of %.3g, %.3g, %.3g um", cc[0], cc[1],
                      cc[2]);
      } else {
        const double A = k * draw.uni(300.0, 700.0), period = draw.uni(15.0, 40.0),
                     ph = draw.uni(0.0, 2 * kPi);
        so.positioning_error_um = [A, period, ph](double x) {
          return A * std::sin(2 * kPi * x / period + ph);
        };
        std::snprintf(buf, sizeof buf, "periodic positioning error %.3g um, period %.3g mm", A,
                      period);
      }
      c.m_um = simulate_four_sensor(cfg, truth, so).m_um;
      c.description = buf;
      break;
    }
    case UndeclaredEffect::traverse: {
      const int i = draw.pick(0, 3);
      const double a2 = k * draw.sign() * draw.uni(1.0, 2.0),
                   a3 = k * draw.sign() * draw.uni(1.0, 2.0);
      for (int n = 0; n < P; ++n) {
        const double u = P > 1 ? 2.0 * n / (P - 1.0) - 1.0 : 0.0;
        c.m_um(n, i) += a2 * legendre(2, u) + a3 * legendre(3, u);
      }
      std::snprintf(buf, sizeof buf, "S not repeating on traverse %d: P2 %.3g um, P3 %.3g um",
                    i + 1, a2, a3);
      c.description = buf;
      break;
    }
    case UndeclaredEffect::nonlinearity: {
      // Relative to the noise-free readings' mid-range: r + κ·(r − r̄)², κ such that the error
      // at the ends of the range is a fraction q of the half range.
      const Eigen::MatrixXd r = c.m_clean_um;
      const double lo = r.minCoeff(), hi = r.maxCoeff(), mid = 0.5 * (lo + hi);
      const double half = std::max(0.5 * (hi - lo), 1e-9);
      const double q = k * draw.sign() * draw.uni(0.02, 0.04);
      const double kappa = q / half;
      c.m_um = c.m_um.array() + kappa * (r.array() - mid).square();
      std::snprintf(buf, sizeof buf,
                    "sensor non-linearity: %+.3g %% of the half range %.3g um at its ends", 100 * q,
                    half);
      c.description = buf;
      break;
    }
    case UndeclaredEffect::bump: {
      const int i = draw.pick(0, 3);
      const double h = k * draw.sign() * draw.uni(1.5, 3.0), w = draw.uni(5.0, 15.0),
                   x0 = draw.uni(0.1 * L, 0.9 * L);
      for (int n = 0; n < P; ++n) {
        const double x = n * cfg.dx_mm;
        c.m_um(n, i) += h * std::exp(-0.5 * std::pow((x - x0) / w, 2));
      }
      std::snprintf(buf, sizeof buf, "bump on traverse %d: %.3g um, %.3g mm wide at %.4g mm", i + 1,
                    h, w, x0);
      c.description = buf;
      break;
    }
    case UndeclaredEffect::hysteresis: {
      // The sensor reads r - h sign(dr/dt) (SequenceEffects::hysteresis_um): on one forward scan
      // the sign of each configuration's noise-free reading's change along x.
      (void)draw.pick(0, 3);  // as the sequence generator draws, so one seed gives the same h
      const double h = k * hysteresis_size_um(draw);
      FourSensorSimOptions s0 = so;
      s0.sigma_um = 0;
      const Eigen::MatrixXd r = simulate_four_sensor(cfg, truth, s0).m_um;
      for (int i = 0; i < 4; ++i)
        for (int n = 0; n < P; ++n) {
          const double slope = r(std::min(n + 1, P - 1), i) - r(std::max(n - 1, 0), i);
          c.m_um(n, i) -= h * (slope > 0 ? 1.0 : slope < 0 ? -1.0 : 0.0);
        }
      std::snprintf(buf, sizeof buf, "sensor hysteresis %.3g um", h);
      c.description = buf;
      break;
    }
  }
  return c;
}

}  // namespace errsep::core

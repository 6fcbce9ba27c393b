#include "errsep/core/model_effect.hpp"

#include <algorithm>

#include "errsep/core/effect_drift.hpp"
#include "errsep/core/effect_gain.hpp"
#include "errsep/core/effect_periodic.hpp"
#include "errsep/core/effect_sensor_offset.hpp"
#include "errsep/core/effect_slide_positioning.hpp"
#include "errsep/core/effect_thermal_drift.hpp"
#include "errsep/core/effect_traverse.hpp"

namespace errsep::core {

double grid_derivative(const Eigen::VectorXd& v, double h, Eigen::Index j) {
  const Eigen::Index n = v.size();
  if (n < 2) return 0.0;
  if (j <= 0) return (v(1) - v(0)) / h;
  if (j >= n - 1) return (v(n - 1) - v(n - 2)) / h;
  return (v(j + 1) - v(j - 1)) / (2.0 * h);
}

Eigen::VectorXd spline_second_derivatives(const Eigen::VectorXd& v, double h) {
  const Eigen::Index n = v.size();
  Eigen::VectorXd m2 = Eigen::VectorXd::Zero(n);
  if (n < 3) return m2;
  // Uniform knots: m_{j-1} + 4 m_j + m_{j+1} = 6 (v_{j-1} − 2 v_j + v_{j+1}) / h², natural ends
  // (m_0 = m_{n-1} = 0); Thomas algorithm.
  const Eigen::Index k = n - 2;
  Eigen::VectorXd c(k), d(k);
  for (Eigen::Index j = 0; j < k; ++j) {
    const double rhs = 6.0 * (v(j) - 2.0 * v(j + 1) + v(j + 2)) / (h * h);
    const double denom = 4.0 - (j > 0 ? c(j - 1) : 0.0);
    c(j) = 1.0 / denom;
    d(j) = (rhs - (j > 0 ? d(j - 1) : 0.0)) / denom;
  }
  for (Eigen::Index j = k - 1; j >= 0; --j)
    m2(j + 1) = d(j) - (j + 1 < k ? c(j) * m2(j + 2) : 0.0);
  return m2;
}

double spline_eval(const Eigen::VectorXd& v, const Eigen::VectorXd& m2, double h, double x,
                   bool deriv) {
  const Eigen::Index n = v.size();
  if (n == 0) return 0.0;
  if (n == 1) return deriv ? 0.0 : v(0);
  const double xmax = static_cast<double>(n - 1) * h;
  const double s0 = (v(1) - v(0)) / h - h * (2.0 * m2(0) + m2(1)) / 6.0;
  const double s1 = (v(n - 1) - v(n - 2)) / h + h * (m2(n - 2) + 2.0 * m2(n - 1)) / 6.0;
  if (x <= 0) return deriv ? s0 : v(0) + x * s0;
  if (x >= xmax) return deriv ? s1 : v(n - 1) + (x - xmax) * s1;
  const Eigen::Index j = std::min<Eigen::Index>(static_cast<Eigen::Index>(x / h), n - 2);
  const double a = (static_cast<double>(j + 1) * h - x) / h, b = 1.0 - a;
  if (!deriv)
    return a * v(j) + b * v(j + 1) +
           ((a * a * a - a) * m2(j) + (b * b * b - b) * m2(j + 1)) * h * h / 6.0;
  return (v(j + 1) - v(j)) / h - (3.0 * a * a - 1.0) / 6.0 * h * m2(j) +
         (3.0 * b * b - 1.0) / 6.0 * h * m2(j + 1);
}

namespace {
constexpr int kLagrangePoints = 8;

// Lagrange weights (value or derivative in units of the grid step) at t for nodes s..s+m-1.
void lagrange_weights(int s, int m, double t, bool deriv, double* w) {
  for (int k = 0; k < m; ++k) {
    const double tk = s + k;
    if (!deriv) {
      double v = 1.0;
      for (int l = 0; l < m; ++l)
        if (l != k) v *= (t - (s + l)) / (tk - (s + l));
      w[k] = v;
    } else {
      double d = 0.0;  // Σ_l [1/(t_k − t_l)]·Π_{q ≠ k, l} (t − t_q)/(t_k − t_q)
      for (int l = 0; l < m; ++l) {
        if (l == k) continue;
        double v = 1.0 / (tk - (s + l));
        for (int q = 0; q < m; ++q)
          if (q != k && q != l) v *= (t - (s + q)) / (tk - (s + q));
        d += v;
      }
      w[k] = d;
    }
  }
}
}  // namespace

Eigen::RowVectorXd reference_interpolation_weights(int N, double h, double y, bool deriv) {
  Eigen::RowVectorXd w = Eigen::RowVectorXd::Zero(N);
  if (N <= 0) return w;
  if (N == 1) {
    if (!deriv) w(0) = 1.0;
    return w;
  }
  const int m = std::min(kLagrangePoints, N);
  double buf[kLagrangePoints];
  const double t = y / h, tmax = N - 1;
  if (t < 0 || t > tmax) {  // linear extrapolation from the end's value and slope
    const bool lo = t < 0;
    const double te = lo ? 0.0 : tmax;
    const int s = lo ? 0 : N - m;
    lagrange_weights(s, m, te, true, buf);
    for (int k = 0; k < m; ++k)
      w(s + k) = buf[k] * (deriv ? 1.0 / h : (t - te));
    if (!deriv) w(lo ? 0 : N - 1) += 1.0;
    return w;
  }
  const int j = std::min(static_cast<int>(t), N - 2);
  const int s = std::clamp(j - (m / 2 - 1), 0, N - m);
  lagrange_weights(s, m, t, deriv, buf);
  for (int k = 0; k < m; ++k)
    w(s + k) = deriv ? buf[k] / h : buf[k];
  return w;
}

double reference_interpolate(const Eigen::VectorXd& f, double h, double y, bool deriv) {
  const int N = static_cast<int>(f.size());
  if (N == 0) return 0.0;
  if (N == 1) return deriv ? 0.0 : f(0);
  const int m = std::min(kLagrangePoints, N);
  double buf[kLagrangePoints];
  const double t = y / h, tmax = N - 1;
  if (t < 0 || t > tmax) {
    const bool lo = t < 0;
    const double te = lo ? 0.0 : tmax;
    const int s = lo ? 0 : N - m;
    lagrange_weights(s, m, te, true, buf);
    double slope = 0;  // per grid step
    for (int k = 0; k < m; ++k)
      slope += buf[k] * f(s + k);
    return deriv ? slope / h : f(lo ? 0 : N - 1) + (t - te) * slope;
  }
  const int j = std::min(static_cast<int>(t), N - 2);
  const int s = std::clamp(j - (m / 2 - 1), 0, N - m);
  lagrange_weights(s, m, t, deriv, buf);
  double v = 0;
  for (int k = 0; k < m; ++k)
    v += buf[k] * f(s + k);
  return deriv ? v / h : v;
}

void EffectContext::prepare() {
  S_m2_ = spline_second_derivatives(S_um, cfg.dx_mm);
  g_m2_ = spline_second_derivatives(gamma_rad, cfg.dx_mm);
}
double EffectContext::f_at(double y) const {
  return reference_interpolate(f_um, cfg.dx_mm, y, false);
}
double EffectContext::f_slope_at(double y) const {
  return reference_interpolate(f_um, cfg.dx_mm, y, true);
}
double EffectContext::S_at(double x) const {
  return spline_eval(S_um, S_m2_, cfg.dx_mm, x, false);
}
double EffectContext::S_slope_at(double x) const {
  return spline_eval(S_um, S_m2_, cfg.dx_mm, x, true);
}
double EffectContext::gamma_at(double x) const {
  return spline_eval(gamma_rad, g_m2_, cfg.dx_mm, x, false);
}
double EffectContext::gamma_slope_at(double x) const {
  return spline_eval(gamma_rad, g_m2_, cfg.dx_mm, x, true);
}

std::string ModelEffect::description(const Eigen::VectorXd&) const {
  return description();
}

Eigen::MatrixXd ModelEffect::f_shift_mm(const Eigen::VectorXd&, const FourSensorConfig&) const {
  return {};
}

Eigen::Vector4d ModelEffect::lever_arm_error_mm(const Eigen::VectorXd&) const {
  return Eigen::Vector4d::Zero();
}

std::vector<std::unique_ptr<ModelEffect>> ModelEffect::variants(const EffectContext&) const {
  std::vector<std::unique_ptr<ModelEffect>> v;
  v.push_back(clone());
  return v;
}

double ModelEffect::effective_trials(const EffectContext&) const {
  return 1.0;
}

std::vector<std::unique_ptr<ModelEffect>> default_effect_library() {
  std::vector<std::unique_ptr<ModelEffect>> lib;
  lib.push_back(std::make_unique<SensorOffsetEffect>());
  lib.push_back(std::make_unique<GainEffect>());
  lib.push_back(std::make_unique<DriftEffect>());
  lib.push_back(std::make_unique<SlidePositioningEffect>());
  lib.push_back(std::make_unique<PeriodicEffect>());
  lib.push_back(std::make_unique<ThermalDriftEffect>());
  lib.push_back(std::make_unique<TraverseEffect>(1, 4));
  return lib;
}

std::string ModelEffect::implausibility(const Eigen::VectorXd& /*p*/,
                                        const EffectContext& /*ctx*/) const {
  return {};
}

}  // namespace errsep::core

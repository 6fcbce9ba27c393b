#pragma once
// A candidate physical effect missing from the four-sensor model (Zhao et al. 2019, Eq. 1), as a
// correction of the sensor outputs: with parameters p the corrected readings
//
//   m_c = m − correction(p)          (P × 4)
//
// obey Eq. (1) again, so the base solver runs unchanged on m_c.  The refinement loop (refine.hpp)
// needs the Jacobian of the modelled readings with respect to p, J = −∂m_c/∂p, evaluated at the
// current estimate of f, S, γ and e (the correction of a non-linear effect such as PE1 or PE2
// depends on the slope of f̂; the loop is Gauss–Newton with f, S, γ, e eliminated by projection).
#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "errsep/core/four_sensor_config.hpp"

namespace errsep::core {

/// The current estimate of the base model, from a least-squares solve of the corrected readings.
struct EffectContext {
  FourSensorConfig cfg;
  Eigen::MatrixXd m_um;       ///< raw readings, P × 4
  Eigen::MatrixXd t_s;        ///< reading times, P × 4 (scan order when none were recorded)
  Eigen::VectorXd f_um;       ///< f̂(x_0..x_{N−1})
  Eigen::VectorXd S_um;       ///< Ŝ(x_n), P
  Eigen::VectorXd gamma_rad;  ///< γ̂(x_n), P
  Eigen::Vector4d e_um = Eigen::Vector4d::Zero();
  Eigen::MatrixXd residual_um;  ///< P × 4 reading residual of the current model (for searches)

  /// Interpolants through f̂ (reference_interpolation_weights), Ŝ and γ̂ (natural cubic splines
  /// over the slide positions): the shifted samples PE1 and PE2 need.  Call prepare() after
  /// setting the profiles; linear extrapolation outside the grid.
  void prepare();
  double f_at(double y_mm) const;
  double f_slope_at(double y_mm) const;  ///< µm/mm
  double S_at(double x_mm) const;
  double S_slope_at(double x_mm) const;  ///< µm/mm
  double gamma_at(double x_mm) const;
  double gamma_slope_at(double x_mm) const;  ///< rad/mm

  /// f̂′ at reference sample j, µm/mm (from the spline).
  double f_slope(int j) const { return f_slope_at(j * cfg.dx_mm); }

 private:
  Eigen::VectorXd S_m2_, g_m2_;  // spline second derivatives
};

/// How f between its samples is modelled (PE1, PE2 and the periodic error sample it there): the
/// 8-point Lagrange interpolant (degree 7) on the nearest samples, the stencil moved inward at the
/// ends, and linear extrapolation from the end value and slope outside [0, (N − 1)·h].  Weights w
/// (N, mostly zero) with f(y) = w·f (deriv: f′(y) = w·f, per mm).  Why not the natural cubic
/// spline: its interpolation error, (5/384)·h⁴·|f⁗|, is 0.05 µm for the 34 mm component of
/// Zhao 2019 Eq. (24) at Δx = 5 mm, twice a 0.02 µm noise, and it biased PE1's dD2 by 0.8 of its
/// standard uncertainty; the 8-point interpolant's error there is ~0.003 µm.
Eigen::RowVectorXd reference_interpolation_weights(int N, double h, double y, bool deriv);
/// The same as a value: w·f for samples f.
double reference_interpolate(const Eigen::VectorXd& f, double h, double y, bool deriv);

/// Natural cubic spline through v sampled every h from 0: second derivatives at the knots.
Eigen::VectorXd spline_second_derivatives(const Eigen::VectorXd& v, double h);
/// Value (deriv = false) or first derivative (deriv = true) of that spline at x.
double spline_eval(const Eigen::VectorXd& v, const Eigen::VectorXd& m2, double h, double x,
                   bool deriv);

/// First derivative of samples v spaced h apart (central inside, one-sided at the ends).
double grid_derivative(const Eigen::VectorXd& v, double h, Eigen::Index j);

class ModelEffect {
 public:
  virtual ~ModelEffect() = default;
  /// Short identifier used in reports and model names, e.g. "gain", "pe1".
  virtual std::string name() const = 0;
  /// One line for the report.
  virtual std::string description() const = 0;
  /// The same for fitted parameters p, where a structural value was refined (the periodic error's
  /// period, the thermal drift's τ).  Default: description().
  virtual std::string description(const Eigen::VectorXd& p) const;
  /// Parameter names with unit suffix, e.g. "dD2_mm".  Their number is the effect's k.
  virtual std::vector<std::string> parameter_names() const = 0;
  int parameter_count() const { return static_cast<int>(parameter_names().size()); }
  /// The correction subtracted from the raw readings (P × 4).
  virtual Eigen::MatrixXd correction_um(const Eigen::VectorXd& p,
                                        const EffectContext& ctx) const = 0;
  /// J = −∂m_c/∂p, 4P × k, row 4n + i (reading of configuration i at x_n).
  virtual Eigen::MatrixXd jacobian(const Eigen::VectorXd& p, const EffectContext& ctx) const = 0;
  /// For an effect that moves the point where the sensor samples the reference surface (PE1,
  /// PE2, the periodic positioning error): that shift, P × 4 mm, reading (n, i) seeing f at
  /// x_n + O_i + shift(n, i).  correction_um must then contain f̂(y + shift) − f̂(y) (y =
  /// x_n + O_i) plus whatever else the effect does.  The refinement fits f at the shifted points
  /// exactly (variable projection: the design of Eq. (1) with interpolation weights at the
  /// shifted points) instead of trusting f̂ from the previous fit, which diverges for shifts of a
  /// few mm on a wavy f.  Empty (the default): the effect does not move the sampling point.
  virtual Eigen::MatrixXd f_shift_mm(const Eigen::VectorXd& p, const FourSensorConfig& cfg) const;
  /// For an effect that moves the sensor (PE1): the error δO_i of the offsets by which γ enters
  /// Eq. (1) (the reading is S + (O_i + δO_i)·γ + …); correction_um must then contain
  /// 1000·δO_i·γ̂(x_n).  The refinement eliminates S and γ per position with the actual offsets.
  /// Default: zero.
  virtual Eigen::Vector4d lever_arm_error_mm(const Eigen::VectorXd& p) const;
  /// Versions of this effect to score (an effect with a structural choice such as a period
  /// returns one per choice).  Default: a copy of itself.
  virtual std::vector<std::unique_ptr<ModelEffect>> variants(const EffectContext& ctx) const;
  /// How many independent trials `variants` amounts to, for the look-elsewhere correction of the
  /// best variant's p-value (Šidák: 1 − (1 − p)^M).  Default 1.
  virtual double effective_trials(const EffectContext& ctx) const;
  /// Physical plausibility of fitted parameters p: empty when they are within the range a real
  /// instrument can have, otherwise why not (e.g. "|g4| = 2.14 > 0.1").  An effect whose fit
  /// leaves that range is "explaining" a residual it did not cause, and the loop does not add
  /// it.  Default: no bound known (always plausible).
  virtual std::string implausibility(const Eigen::VectorXd& p, const EffectContext& ctx) const;
  virtual std::unique_ptr<ModelEffect> clone() const = 0;
};

/// The library: pe1, gain, drift, pe2, periodic, thermal, traverse (one file each).
std::vector<std::unique_ptr<ModelEffect>> default_effect_library();

}  // namespace errsep::core

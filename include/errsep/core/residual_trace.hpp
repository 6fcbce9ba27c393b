#pragma once
// The residual of the four-sensor model traced against everything a scan records (issue 16,
// item 3): reading time, slide position, configuration, reading level, direction and temperature.
//
// A missing effect that is a smooth function of a recorded variable v leaves a residual
// r = Π·(Z(v)·β + ε), Π the projector onto the complement of the model's columns in the reduced
// space (residual_analysis.hpp).  For each variable the trace adds the columns Z(v) (Legendre
// polynomials of v scaled to [−1, 1], per configuration where a sensor position can differ) to the
// model and tests them with the ordinary F-test of nested least-squares models,
//   F = (ΔRSS/k)/((RSS − ΔRSS)/(dof − k)),   k = directions of Π·Z that do not vanish,
// which is exactly F(k, dof − k) under Gaussian noise for columns that do not depend on the noise
// (time, position, direction, temperature).  The reading level m does contain the noise; its
// columns are then correlated with the residual at order σ/range (0.1 µm against readings that
// span some µm), which the clean false-alarm rate of tests/core/residual_trace checks.
// The configuration's own test (is one sensor position noisier than the others?) compares the
// per-configuration residual energy with its expectation under the projector; its null
// distribution has no closed form, so it is calibrated by Monte-Carlo draws of Π·ε (exact for
// Gaussian noise, as the whiteness test).  Each test's p-value is multiplied by the number of
// tests carried out (Bonferroni), so on a complete model the trace reports a dependence in at
// most a fraction α of scans.
//
// A sensor non-linearity (not in the effect library): the one sensor of the single-sensor system
// reads m = r + c₂·a² (+ c₃·a³), a = r − mid, at all four configurations.  With Eq. (1)'s
// r_i(x) = f(x + D_i) + S(x) + O_i·γ(x) + e_i and g_i = f(x + D_i) + e_i − mid,
//   a² = g_i² + 2·g_i·(S + O_i·γ) + (S + O_i·γ)²,
// and the model absorbs: f(x + D_i)² and every other function of f's sample alone (f is free per
// sample), the constants e_i², and per position everything affine in O_i (S², 2·O_i·S·γ and the
// parts of the other terms along 1 and O_i: S and γ take them).  What is left for the residual is
// the part of the cross term 2·(f(x + D_i) − mid)·(S(x) + O_i·γ(x)) that is not affine in O_i,
// plus the small 2·e_i·(S + O_i·γ) and O_i²·γ².  On the paper's geometry with random smooth
// profiles only about a tenth of the norm of c₂·a² is in the residual (the finding prints the
// fraction), so a non-linearity can double the S error while showing ~3 σ in the residual; a
// plan that repeats configurations at the same reading levels (closing pass, reversed) shows
// nothing more, since the non-linearity repeats too; a configuration measured again with the
// sensor re-zeroed by Δ would show the slope difference 2·c₂·Δ over the whole traverse.
// The test is the score test of c₂ (c₃): the F test of the single column ∂m/∂c = a² (a³) at the
// fitted readings (one degree of freedom, the non-linearity's own signature).  Per configuration
// the reading level is also traced with Legendre columns of degree 1..level_degree (a gain or a
// non-linearity of one sensor position).
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "errsep/core/residual_analysis.hpp"

namespace errsep::core {

/// What the scan recorded besides the readings, each P × 4 like them (row = position,
/// column = configuration); empty when not recorded.
struct RecordedVariables {
  Eigen::MatrixXd t_s;            ///< reading times (empty: scan order, scan_order_times_s)
  Eigen::MatrixXd direction;      ///< +1 forward, −1 backward (empty: not recorded)
  Eigen::MatrixXd temperature_C;  ///< temperature at each reading (empty: not recorded)
};

struct ResidualTraceOptions {
  double alpha = 0.01;         ///< family-wise level over all tests of the trace
  int time_degree = 3;         ///< Legendre degrees of each variable's columns
  int position_degree = 3;     ///< per configuration
  int level_degree = 3;        ///< per configuration (the common test is c₂·a² and c₃·a³)
  int temperature_degree = 2;  ///< common to all configurations
  int mc_samples = 400;        ///< draws for the configuration test
  std::uint64_t seed = 11;     ///< fixed: the same data give the same report
  bool is_valid(std::string* why = nullptr) const;
};

/// One variable's test.
struct DependenceTest {
  std::string variable;  ///< "time", "position", "configuration", "reading level", ...
  bool tested = false;
  std::string not_tested;  ///< why not (not recorded, constant, nothing identifiable)
  int parameters = 0;      ///< columns tried
  int identifiable = 0;    ///< directions left after the model's own columns
  double statistic = 0;    ///< F, or for "configuration" the largest energy ratio
  double p_value = 1;      ///< of this test alone
  double p_adjusted = 1;   ///< times the number of tests carried out (Bonferroni), at most 1
  /// Fitted coefficients of the test's columns: of the Legendre terms P_1..P_d (µm) for the
  /// polynomial tests, of a² (1/µm) or a³ (1/µm²) for the common non-linearity tests.  For the
  /// reading level also: `kappa_per_um`, the quadratic coefficient in m (with its standard
  /// uncertainty for the common test), `kappa3_per_um2` the cubic one, and `nonlinear_um`, the
  /// largest departure of the non-linear part over the readings' range.
  Eigen::VectorXd coefficients_um;
  double kappa_per_um = 0, u_kappa_per_um = 0;
  double kappa3_per_um2 = 0, u_kappa3_per_um2 = 0;
  double nonlinear_um = 0;
  /// Common non-linearity tests: ‖Π·z‖/‖z‖, the fraction of the signature z = a² (a³) that the
  /// model cannot absorb (the rest changes f, S, γ, e without a trace in the residual).
  double visible_fraction = 0;
  double range_lo_um = 0, range_hi_um = 0;
  bool significant = false;  ///< p_adjusted < alpha
  std::string finding;       ///< one line when significant, else empty
};

struct ResidualTrace {
  std::vector<DependenceTest> tests;
  int tests_run = 0;
  double p_value = 1;    ///< smallest p_adjusted
  bool depends = false;  ///< some test significant at the family-wise alpha
  double alpha = 0.01;
  std::vector<std::string> findings;  ///< the significant tests' lines
  std::string brief_report() const;
};

/// Traces the residual of the readings `m_um` (P × 4, corrected for any effects already in the
/// model) against `recorded` under the model `space`.  Throws std::invalid_argument for shape
/// mismatches or invalid options.
ResidualTrace trace_residual(const ResidualSpace& space, const Eigen::MatrixXd& m_um,
                             const RecordedVariables& recorded = {},
                             const ResidualTraceOptions& opts = {});

/// A scan sequence's readings and what it recorded of each, P × T (column k = traverse k,
/// row n = slide position n; scan_sequence.hpp), with the fit's column space.
struct SequenceTraceInput {
  /// PT × p orthonormal basis of the fit's columns (row k·P + n): the residual is the
  /// readings' part orthogonal to it.
  Eigen::MatrixXd basis;
  Eigen::MatrixXd m_um;            ///< P × T readings
  Eigen::MatrixXd t_s;             ///< P × T reading times
  std::vector<int> configuration;  ///< T, 0..3
  std::vector<int> direction;      ///< T, +1 forward, −1 backward
  double dx_mm = 1.0;
};

/// The trace of every reading of a scan sequence under its fit (sequence_refine.hpp): time
/// (common), position (per configuration), reading level (the common non-linearity's score
/// columns a², a³ at the fitted readings, as trace_residual) and direction.  Direction, for each
/// configuration measured both ways: an offset of its backward traverses, and a hysteresis of the
/// sensor — it reads r − h·sign(dr/dt), lagging behind the surface in the direction its reading
/// changes; with the slide moving at ±v, dr/dt = ±v·dr/dx, so the column is
/// −(direction)·sign(dr̂/dx) of the fitted readings (its coefficient h, µm).  On a traverse with
/// its own zero adjustment a constant offset is absorbed; the hysteresis alternates with the
/// profile's slope and is not.  A configuration measured in one direction only cannot show it:
/// with none measured both ways the direction test is not run ("not identifiable from this
/// plan").  The fitted readings carry the noise Hε, independent of the residual under Gaussian
/// noise, so the F tests are exact; Bonferroni over the tests run, as trace_residual.
/// Throws std::invalid_argument for inconsistent shapes or invalid options.
ResidualTrace trace_sequence_residual(const SequenceTraceInput& in,
                                      const ResidualTraceOptions& opts = {});

/// Diagonal of the reading-space residual projector (P × 4): the variance of each reading's
/// residual in units of σ².  0 for a reading the model fits exactly.
Eigen::MatrixXd reading_projector_diagonal(const ResidualSpace& space);

}  // namespace errsep::core

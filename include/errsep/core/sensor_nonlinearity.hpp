#pragma once
// A sensor non-linearity found by the residual trace (residual_trace.hpp), taken out of the
// separation only when that makes S, γ and f better, and otherwise carried in u (issue 16,
// item 3; not in the effect library).
//
// The trace's score test gives the quadratic coefficient c₂ ± u of m = r + c₂·(r − mid)² at the
// fitted readings.  Its column z = (m − mid)² (P × 4) changes the separation by D·c₂, D the
// sensitivities of S, γ, f to −z at the separation's λ (gauge directions removed: a step never
// moves what the data cannot see).  Most of z is absorbed by f, S and γ (the trace prints the
// visible fraction, ~5 % of its norm on random profiles), so c₂ is determined only by the small
// visible part while D can be large: decide_step (step_decision.hpp) weighs the correction's
// scatter D·u against the bias D·ĉ₂ of leaving it in.  Applied: the readings minus ĉ₂·z are
// separated again, u widened by D·u.  Left in: u widened by D·ĉ₂ (and D·u), so a non-linearity
// the trace finds is at least covered.
#include <Eigen/Core>
#include <string>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/residual_trace.hpp"
#include "errsep/core/step_decision.hpp"

namespace errsep::core {

struct NonlinearityStep {
  bool detected = false;  ///< the trace's quadratic reading-level test was significant
  double c2_per_um = 0, u_c2_per_um = 0;
  double mid_um = 0;     ///< the reading about which the quadratic is taken
  bool applied = false;  ///< the readings were corrected
  StepDecision decision;
  double u_S_added_um = 0;  ///< largest widening of u_S
  std::string finding;      ///< one line when detected
};

/// The separation of `m_um` (P × 4) without the non-linearity `trace` found, or `before` (the
/// separation of `m_um`) with u widened by what it could do; `before` unchanged when the trace
/// found none.  `step` (if given) receives the figures.  The result has before's gauge.
FourSensorResult separate_without_nonlinearity(
    const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um, const ResidualTrace& trace,
    const FourSensorResult& before, const FourSensorOptions& solve,
    NonlinearityStep* step = nullptr, const StepDecisionOptions& decision = {});

}  // namespace errsep::core

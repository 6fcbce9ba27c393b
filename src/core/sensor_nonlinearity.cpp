#include "errsep/core/sensor_nonlinearity.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "errsep/core/refine.hpp"

namespace errsep::core {

FourSensorResult separate_without_nonlinearity(
    const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um, const ResidualTrace& trace,
    const FourSensorResult& before, const FourSensorOptions& solve, NonlinearityStep* step_out,
    const StepDecisionOptions& decision) {
  NonlinearityStep step;
  const DependenceTest* t = nullptr;
  for (const auto& d : trace.tests)
    if (d.significant && d.variable == "reading level (quadratic non-linearity)") t = &d;
  if (!t) {
    if (step_out) *step_out = step;
    return before;
  }
  step.detected = true;
  step.c2_per_um = t->kappa_per_um;
  step.u_c2_per_um = t->u_kappa_per_um;
  step.mid_um = 0.5 * (t->range_lo_um + t->range_hi_um);
  const int P = cfg.positions();
  const Eigen::MatrixXd z = (m_um.array() - step.mid_um).square().matrix();
  // Sensitivities of S, γ, f to the correction −c₂·z per unit c₂, at before's λ.
  const FourSensorResult s = separate_four_sensor(cfg, -z, linearised_options(before, solve));
  const Eigen::MatrixXd D_S = remove_polynomial(Eigen::MatrixXd(s.S_um), 2);
  const Eigen::MatrixXd D_g = remove_polynomial(Eigen::MatrixXd(1e6 * s.gamma_rad), 1);
  const Eigen::MatrixXd D_f = s.f_um;
  auto or_ones = [](const Eigen::VectorXd& u, Eigen::Index n) {
    return u.size() == n ? u : Eigen::VectorXd::Ones(n);
  };
  const Eigen::VectorXd uS = or_ones(before.u_S_um, P), ug = or_ones(1e6 * before.u_gamma_rad, P),
                        uf = or_ones(before.u_f_um, cfg.N);
  const Eigen::VectorXd p = Eigen::VectorXd::Constant(1, step.c2_per_um);
  const Eigen::MatrixXd C = Eigen::MatrixXd::Constant(1, 1, step.u_c2_per_um * step.u_c2_per_um);
  step.decision = decide_step(
      p, C, {{"S", "um", D_S, uS}, {"gamma", "urad", D_g, ug}, {"f", "um", D_f, uf}}, decision);
  step.applied = step.decision.apply;
  // Separated again either way, so the widened covariance is the result's own (before's is
  // shared with the caller).
  FourSensorResult after = separate_four_sensor(
      cfg, step.applied ? Eigen::MatrixXd(m_um - step.c2_per_um * z) : m_um, solve);
  after.S_um = before.S_um + remove_polynomial(after.S_um - before.S_um, 2);
  after.gamma_rad = before.gamma_rad + remove_polynomial(after.gamma_rad - before.gamma_rad, 1);
  // Applied: the coefficient's scatter; left in: its fitted size too (the bias of leaving it).
  const double carried = C(0, 0) + (step.applied ? 0.0 : p(0) * p(0));
  auto widen = [&](Eigen::VectorXd& u, const Eigen::MatrixXd& D, double scale) {
    if (u.size() != D.rows()) return;
    u = (u.array().square() + scale * scale * carried * D.col(0).array().square()).sqrt();
  };
  const Eigen::VectorXd u_S_old = after.u_S_um;
  widen(after.u_S_um, D_S, 1.0);
  widen(after.u_gamma_rad, D_g, 1e-6);
  widen(after.u_f_um, D_f, 1.0);
  if (after.covariance)
    after.covariance->add_low_rank(D_S, 1e-6 * D_g, D_f, Eigen::MatrixXd::Constant(1, 1, carried));
  if (u_S_old.size() == after.u_S_um.size() && u_S_old.size() > 0)
    step.u_S_added_um =
        (after.u_S_um.array().square() - u_S_old.array().square()).max(0.0).sqrt().maxCoeff();
  char buf[500];
  std::snprintf(buf, sizeof buf,
                "sensor non-linearity c2 = %.3g +- %.2g /um about %.4g um (not in the effect "
                "library): %s",
                step.c2_per_um, step.u_c2_per_um, step.mid_um,
                step.applied ? "the readings corrected" : "NOT corrected");
  step.finding = buf;
  step.finding += step.applied ? ("; " + step.decision.reason)
                               : (" (" + step.decision.reason + "); u_S widened by up to " +
                                  std::to_string(step.u_S_added_um).substr(0, 5) + " um");
  if (step_out) *step_out = step;
  return after;
}

}  // namespace errsep::core

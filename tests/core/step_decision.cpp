// The step decision (step_decision.hpp) on cases whose answer follows from its definition: one
// parameter with a known sensitivity, the expected squared errors V (applied) and B (left out)
// in units of the quantity's u, and the uncertainty it leaves in the result.
#include <Eigen/Core>
#include <catch2/catch.hpp>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "errsep/core/step_decision.hpp"

using namespace errsep::core;

namespace {
// n points of unit u, the quantity changing by `per_unit` per unit of the one parameter.
std::vector<QuantityImpact> one_quantity(int n, double per_unit) {
  return {{"S", "um", Eigen::MatrixXd::Constant(n, 1, per_unit), Eigen::VectorXd::Ones(n)}};
}
}  // namespace

TEST_CASE("step decision: a well determined effect is applied, a poorly determined one is not") {
  const auto q = one_quantity(10, 1.0);
  const Eigen::MatrixXd C = Eigen::MatrixXd::Constant(1, 1, 0.01);  // u_p = 0.1
  // p = 1 (10 u_p): B = 10 (1 - 0.01) = 9.9, V = 0.1: applied.
  const StepDecision a = decide_step(Eigen::VectorXd::Constant(1, 1.0), C, q);
  CHECK(a.apply);
  CHECK(a.variance_sum == Approx(0.1));
  CHECK(a.bias_sum == Approx(9.9));
  // p = 0.12 (1.2 u_p): B = 10 (0.0144 - 0.01) = 0.044 < 2 V: reported, not applied.
  const StepDecision b = decide_step(Eigen::VectorXd::Constant(1, 0.12), C, q);
  CHECK_FALSE(b.apply);
  const std::string line = describe_decision("gain", {"g3"}, Eigen::VectorXd::Constant(1, 0.12),
                                             Eigen::VectorXd::Constant(1, 0.1), b);
  CHECK(line.find("gain detected (g3 = 0.12 +- 0.1): not applied, adds 0.12 um to u_S") == 0);
  // Two quantities weigh together, each point in its own u: V and B add.
  std::vector<QuantityImpact> two = one_quantity(10, 0.0);
  two.front().sensitivity(0, 0) = 10.0;  // S: one point changes a lot, uncertainly
  two.push_back({"f", "um", Eigen::MatrixXd::Constant(100, 1, 1.0), Eigen::VectorXd::Ones(100)});
  const StepDecision c = decide_step(Eigen::VectorXd::Constant(1, 0.5), C, two);
  // S: V = 1, B = 25 - 1 = 24 at its one point; f: V = 100 * 0.01 = 1, B = 100 * 0.24 = 24.
  CHECK(c.variance_sum == Approx(2.0));
  CHECK(c.bias_sum == Approx(48.0));
  CHECK(c.apply);
  CHECK_THROWS_AS(decide_step(Eigen::VectorXd::Ones(2), C, q), std::invalid_argument);
}

TEST_CASE("step decision: what the linearisation misses counts with the scatter") {
  auto q = one_quantity(10, 1.0);
  const Eigen::MatrixXd C = Eigen::MatrixXd::Constant(1, 1, 0.01);
  const Eigen::VectorXd p = Eigen::VectorXd::Constant(1, 1.0);
  // Without a remainder: V = 0.1, B = 9.9 (the case above), applied.
  REQUIRE(decide_step(p, C, q).apply);
  // A remainder of 0.8 u at every point (the correction at p changes the quantity by 1.8 or 0.2
  // where its linearisation says 1): V = 0.1 + 10 * 0.64 = 6.5 > 0.5 B: not applied; B as before.
  q.front().remainder = Eigen::VectorXd::Constant(10, 0.8);
  const StepDecision d = decide_step(p, C, q);
  CHECK(d.variance_sum == Approx(6.5));
  CHECK(d.bias_sum == Approx(9.9));
  CHECK_FALSE(d.apply);
  CHECK(d.quantity("S")->rms_added_u == Approx(std::sqrt(0.01 + 0.64)));
  // A small one leaves the decision: 0.1 + 10 * 0.01 = 0.2.
  q.front().remainder = Eigen::VectorXd::Constant(10, 0.1);
  CHECK(decide_step(p, C, q).variance_sum == Approx(0.2));
  CHECK(decide_step(p, C, q).apply);
  q.front().remainder = Eigen::VectorXd::Constant(3, 0.1);  // not one per point
  CHECK_THROWS_AS(decide_step(p, C, q), std::invalid_argument);
}

TEST_CASE("step decision: the refined u carries the applied parameters' covariance") {
  const Eigen::VectorXd u = Eigen::VectorXd::Constant(3, 0.3);
  Eigen::MatrixXd D(3, 2);
  D << 1, 0, 2, 1, 0, 3;
  Eigen::MatrixXd C(2, 2);
  C << 0.04, 0.01, 0.01, 0.09;
  const Eigen::VectorXd p = Eigen::Vector2d(0.5, -0.2);
  // Both applied: u^2 + diag(D C D').
  const Eigen::VectorXd ua = refined_uncertainty(u, D, C, p, {true, true});
  const Eigen::VectorXd va = (D * C * D.transpose()).diagonal();
  for (int i = 0; i < 3; ++i)
    CHECK(ua(i) == Approx(std::sqrt(0.09 + va(i))));
  // The second left out: its fitted size squared instead of its variance.
  const Eigen::VectorXd ul = refined_uncertainty(u, D, C, p, {true, false});
  for (int i = 0; i < 3; ++i) {
    const double var = D(i, 0) * D(i, 0) * C(0, 0), bias = D(i, 1) * p(1);
    CHECK(ul(i) == Approx(std::sqrt(0.09 + var + bias * bias)));
  }
  CHECK_THROWS_AS(refined_uncertainty(u, D, C, p, {true}), std::invalid_argument);
}

// The lower confidence bound of the bias (bias_z): an effect chosen because its fit came out a few
// standard deviations from zero has B ~ (z^2 - 1) V on noise alone; deciding on B - z sd(B)
// keeps such a fit out while a well determined one is still applied.  sd(B) for one parameter:
// M = sum s^2/u^2, Var(B) = 4 p^2 M^2 C + 2 M^2 C^2.
TEST_CASE("step decision: bias_z decides on a lower confidence bound of the bias removed") {
  const auto q = one_quantity(10, 1.0);                             // M = 10
  const Eigen::MatrixXd C = Eigen::MatrixXd::Constant(1, 1, 0.01);  // u_p = 0.1, V = 0.1
  StepDecisionOptions z2;
  z2.bias_z = 2.0;
  // p = 4 u_p: B = 10 (0.16 - 0.01) = 1.5 >= 2 V, applied on B alone; sd(B) =
  // 10 sqrt(4 0.16 0.01 + 2 1e-4) = 0.917, B - 2 sd = -0.33: not applied with bias_z = 2.
  const Eigen::VectorXd p4 = Eigen::VectorXd::Constant(1, 0.4);
  const StepDecision plain = decide_step(p4, C, q);
  CHECK(plain.apply);
  const StepDecision bound = decide_step(p4, C, q, z2);
  CHECK(bound.bias_sum == Approx(1.5));
  CHECK(bound.bias_sd == Approx(10.0 * std::sqrt(4 * 0.16 * 0.01 + 2e-4)));
  CHECK(bound.bias_bound == Approx(1.5 - 2 * bound.bias_sd));
  CHECK_FALSE(bound.apply);
  CHECK(bound.reason.find("lower bound") != std::string::npos);
  // p = 10 u_p: B = 9.9, sd(B) = 10 sqrt(4e-2 + 2e-4) = 2.005, B - 2 sd = 5.9 >= 2 V: applied.
  const StepDecision well = decide_step(Eigen::VectorXd::Constant(1, 1.0), C, q, z2);
  CHECK(well.apply);
  // bias_z = 0 is the plain decision.
  CHECK(decide_step(p4, C, q, StepDecisionOptions{}).bias_bound == Approx(plain.bias_sum));
  StepDecisionOptions bad;
  bad.bias_z = -1;
  CHECK_FALSE(bad.is_valid());
}

// Comparison with an independent reference trace (core/reference_comparison.hpp): interpolation
// to the scan's positions, the best-fit-line alignment of Zhao 2019 section 4, and the deviation.
#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <cmath>
#include <random>
#include <stdexcept>

#include "errsep/core/reference_comparison.hpp"

using namespace errsep::core;

namespace {

// A piecewise-linear "true" profile sampled at the reference's knots is interpolated exactly.
double truth_um(double x) {
  return 2.0 * std::sin(x / 40.0) + 0.5 * std::cos(x / 13.0);
}

}  // namespace

TEST_CASE("rotation and offset between the coordinate systems are removed, a deviation is kept") {
  // Scan every 5 mm over 0..300; the reference every 1 mm over -10..320 (its own grid).
  const Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(61, 0.0, 300.0);
  const Eigen::VectorXd xr = Eigen::VectorXd::LinSpaced(331, -10.0, 320.0);
  Eigen::VectorXd ref(xr.size());
  for (Eigen::Index j = 0; j < xr.size(); ++j)
    ref(j) = truth_um(xr(j));
  // The measured profile: the truth at the scan positions (on the reference's knots, so the
  // interpolation is exact), seen rotated by 20 µrad (0.02 µm/mm) with a 3 µm zero offset, plus a
  // deviation d with no line in it.
  std::mt19937_64 rng(3);
  std::normal_distribution<double> g(0.0, 0.2);
  Eigen::VectorXd d(x.size());
  for (Eigen::Index n = 0; n < x.size(); ++n)
    d(n) = g(rng);
  Eigen::MatrixXd A(x.size(), 2);
  A.col(0).setOnes();
  A.col(1) = x;
  d -= A * A.colPivHouseholderQr().solve(d);  // d orthogonal to the line space
  Eigen::VectorXd measured(x.size());
  for (Eigen::Index n = 0; n < x.size(); ++n)
    measured(n) = truth_um(x(n)) + 3.0 + 0.02 * x(n) + d(n);

  const ReferenceComparison c = compare_with_reference(x, measured, xr, ref);
  CHECK(c.points == 61);
  CHECK(c.points_outside == 0);
  CHECK(c.offset == Approx(3.0).margin(1e-9));
  CHECK(c.slope_per_mm == Approx(0.02).margin(1e-12));
  CHECK((c.difference - d).cwiseAbs().maxCoeff() < 1e-9);
  CHECK(c.rms == Approx(std::sqrt(d.squaredNorm() / 61.0)).epsilon(1e-9));
  CHECK(c.max_abs == Approx(d.cwiseAbs().maxCoeff()).epsilon(1e-9));
  // The alignment is the least 2-norm: any other line leaves more.
  for (double db : {-1e-3, 1e-3}) {
    const Eigen::VectorXd other =
        (measured - c.reference).array() - c.offset - (c.slope_per_mm + db) * x.array();
    CHECK(other.norm() > c.difference.norm());
  }
}

TEST_CASE(
    "reference between its samples is interpolated linearly, positions outside are left out") {
  // Reference every 10 mm from 20 to 200 of a piecewise-linear trace: exact at every scan point.
  const Eigen::VectorXd xr = Eigen::VectorXd::LinSpaced(19, 20.0, 200.0);
  Eigen::VectorXd ref(xr.size());
  for (Eigen::Index j = 0; j < xr.size(); ++j)
    ref(j) = (j % 2 == 0) ? 1.0 : -1.0;  // a zig-zag
  const Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(61, 0.0, 300.0);
  Eigen::VectorXd measured(x.size());
  for (Eigen::Index n = 0; n < x.size(); ++n) {
    const double u = (x(n) - 20.0) / 10.0;
    const double frac = u - std::floor(u);
    const int j = static_cast<int>(std::floor(u));
    const double a = (j % 2 == 0) ? 1.0 : -1.0;
    measured(n) = a + (-2.0 * a) * frac;  // the same zig-zag between knots
  }
  ReferenceCompareOptions o;
  o.alignment = ReferenceAlignment::none;
  const ReferenceComparison c = compare_with_reference(x, measured, xr, ref, o);
  CHECK(c.points == 37);  // 20, 25, ..., 200
  CHECK(c.points_outside == 24);
  CHECK(c.x_mm(0) == 20.0);
  CHECK(c.x_mm(c.points - 1) == 200.0);
  CHECK(c.max_abs < 1e-12);
  // The mean-only alignment (γ) removes a constant and nothing else.
  o.alignment = ReferenceAlignment::offset;
  const Eigen::VectorXd shifted = measured.array() + 0.7;
  const ReferenceComparison c2 = compare_with_reference(x, shifted, xr, ref, o);
  CHECK(c2.offset == Approx(0.7));
  CHECK(c2.slope_per_mm == 0.0);
  CHECK(c2.max_abs < 1e-12);
}

TEST_CASE("bad reference traces are refused with a reason") {
  const Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(11, 0.0, 50.0);
  const Eigen::VectorXd m = Eigen::VectorXd::Zero(11);
  Eigen::VectorXd xr = Eigen::VectorXd::LinSpaced(6, 0.0, 50.0);
  const Eigen::VectorXd r = Eigen::VectorXd::Zero(6);
  xr(3) = xr(2);  // not increasing
  CHECK_THROWS_WITH(compare_with_reference(x, m, xr, r), Catch::Contains("must increase"));
  const Eigen::VectorXd far = Eigen::VectorXd::LinSpaced(6, 100.0, 150.0);
  CHECK_THROWS_WITH(compare_with_reference(x, m, far, r), Catch::Contains("only 0 scan positions"));
  Eigen::VectorXd rn = r;
  rn(1) = std::nan("");
  CHECK_THROWS_AS(compare_with_reference(x, m, Eigen::VectorXd::LinSpaced(6, 0.0, 50.0), rn),
                  std::invalid_argument);
  CHECK_THROWS_AS(compare_with_reference(x, Eigen::VectorXd::Zero(3), far, r),
                  std::invalid_argument);
}

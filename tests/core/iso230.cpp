// ISO 230-1 figures on profiles whose values are known in closed form.
#include "errsep/core/iso230.hpp"

#include <catch2/catch.hpp>
#include <cmath>
#include <random>
#include <vector>

using namespace errsep::core;

namespace {

constexpr double kPi = 3.14159265358979323846;
const ReferenceLine kAllLines[] = {ReferenceLine::end_points, ReferenceLine::least_squares,
                                   ReferenceLine::minimum_zone};

std::vector<double> grid(double x0, double x1, std::size_t n) {
  std::vector<double> x(n);
  for (std::size_t i = 0; i < n; ++i)
    x[i] = x0 + (x1 - x0) * static_cast<double>(i) / static_cast<double>(n - 1);
  return x;
}

// Minimum-zone straightness of A sin(2 pi x / L) over one period, from the equal-ripple
// condition: the zone of slope -t (t in units of A per radian) touches the interior maximum
// (cos th = -t) and the end point, sqrt(1 - t^2) - t acos(t) = t pi; the width is 2 pi t A.
double sine_minimum_zone_width() {
  double lo = 0, hi = 1;
  for (int i = 0; i < 200; ++i) {
    const double t = (lo + hi) / 2;
    const double g = std::sqrt(1 - t * t) - t * std::acos(t) - t * kPi;
    (g > 0 ? lo : hi) = t;
  }
  return 2 * kPi * (lo + hi) / 2;
}

}  // namespace

TEST_CASE("pure bow: all three reference lines give the sagitta, also when tilted") {
  const double L = 1000, h = 12.5;
  const auto x = grid(0, L, 201);  // the midpoint x = L/2 is a sample
  for (const double tilt : {0.0, 0.02, -0.05}) {
    std::vector<double> s(x.size());
    for (std::size_t i = 0; i < x.size(); ++i)
      s[i] = 4 * h * (x[i] / L) * (1 - x[i] / L) + 3.0 + tilt * x[i];
    for (const auto ref : kAllLines) {
      INFO(to_string(ref) << " tilt " << tilt);
      const auto r = evaluate_straightness(x, s, {}, ref);
      CHECK(r.straightness_um == Approx(h).epsilon(1e-9));
      CHECK(r.index_max == 100);  // the bow's top, for every reference (convex profile)
    }
    // Least squares and end points must recover the tilt of a symmetric bow.
    CHECK(evaluate_straightness(x, s, {}, ReferenceLine::end_points).line.slope_um_per_mm ==
          Approx(tilt).margin(1e-12));
    CHECK(evaluate_straightness(x, s, {}, ReferenceLine::least_squares).line.slope_um_per_mm ==
          Approx(tilt).margin(1e-12));
  }
}

TEST_CASE("tilted straight line: straightness is zero for all three reference lines") {
  const auto x = grid(-200, 300, 57);
  std::vector<double> s(x.size());
  for (std::size_t i = 0; i < x.size(); ++i)
    s[i] = -4.0 + 0.037 * x[i];
  for (const auto ref : kAllLines) {
    INFO(to_string(ref));
    const auto r = evaluate_straightness(x, s, {}, ref);
    CHECK(r.straightness_um == Approx(0).margin(1e-11));
    CHECK(r.line.slope_um_per_mm == Approx(0.037).margin(1e-12));
  }
}

TEST_CASE("one sine period: end points 2A, least squares 6A/pi, minimum zone from equal ripple") {
  // Closed forms for A sin(2 pi x / L) on [0, L]:
  //  - end-point line is s = 0: 2A;
  //  - least squares, for the N = M + 1 samples x_i = i h (h = L / M), exactly:
  //      sum (x_i - L/2) s_i = -A h M cot(pi / M) / 2,   sum (x_i - L/2)^2 = N (N^2 - 1) h^2 / 12,
  //    so b = -6 A M cot(pi/M) / (N (N^2 - 1) h)  (-> -6A/(pi L) for large N); the extremes of
  //    the residual are at the two ends, range |b| L (-> 6A/pi);
  //  - minimum zone: see sine_minimum_zone_width() (about 1.3647 A) for the continuous profile;
  //    sampling 2001 points moves the interior extreme by less than A (2 pi / 2000)^2 / 8,
  //    tolerance 1e-5 relative.
  const double L = 400, A = 3.0;
  const auto x = grid(0, L, 2001);
  std::vector<double> s(x.size());
  for (std::size_t i = 0; i < x.size(); ++i)
    s[i] = A * std::sin(2 * kPi * x[i] / L);
  const auto ep = evaluate_straightness(x, s, {}, ReferenceLine::end_points);
  const auto ls = evaluate_straightness(x, s, {}, ReferenceLine::least_squares);
  const auto mz = evaluate_straightness(x, s, {}, ReferenceLine::minimum_zone);
  CHECK(ep.straightness_um == Approx(2 * A).epsilon(1e-5));
  const double M = 2000, N = 2001, h = L / M;
  const double b = -6 * A * M / std::tan(kPi / M) / (N * (N * N - 1) * h);
  CHECK(ls.line.slope_um_per_mm == Approx(b).epsilon(1e-12));
  CHECK(ls.straightness_um == Approx(-b * L).epsilon(1e-12));
  CHECK(ls.straightness_um == Approx(6 * A / kPi).epsilon(2e-3));  // continuum limit, 3/N away
  const double mz_expected = sine_minimum_zone_width() * A;
  CHECK(sine_minimum_zone_width() == Approx(1.3647).epsilon(1e-3));  // the equation, sanity
  CHECK(mz.straightness_um == Approx(mz_expected).epsilon(1e-5));
  // The minimum zone is never wider than the other two.
  CHECK(mz.straightness_um <= ls.straightness_um);
  CHECK(mz.straightness_um <= ep.straightness_um);
}

TEST_CASE("minimum zone is the smallest zone over all slopes (random polylines)") {
  std::mt19937 rng(7);
  std::normal_distribution<double> nd(0, 1);
  for (int trial = 0; trial < 20; ++trial) {
    const std::size_t n = 5 + static_cast<std::size_t>(trial) * 7;
    auto x = grid(0, 100, n);
    std::vector<double> s(n);
    for (auto& v : s)
      v = nd(rng);
    const auto mz = evaluate_straightness(x, s, {}, ReferenceLine::minimum_zone);
    auto width = [&](double b) {
      double mx = -1e300, mn = 1e300;
      for (std::size_t i = 0; i < n; ++i) {
        mx = std::max(mx, s[i] - b * x[i]);
        mn = std::min(mn, s[i] - b * x[i]);
      }
      return mx - mn;
    };
    CHECK(width(mz.line.slope_um_per_mm) == Approx(mz.straightness_um).epsilon(1e-12));
    // A dense scan of slopes never finds a narrower zone.
    for (int k = -2000; k <= 2000; ++k) {
      const double b = mz.line.slope_um_per_mm + k * 1e-5;
      REQUIRE(width(b) >= mz.straightness_um - 1e-12);
    }
  }
}

TEST_CASE("sensitivities are invariant to adding a line, and the uncertainty matches Monte Carlo") {
  // A tent profile: sharp extremes, so small noise never changes the active points and the
  // linearised propagation is exact; Monte Carlo with 4000 draws checks u_uncorrelated to ~2 %.
  const double L = 500, h = 8;
  const auto x = grid(0, L, 101);
  std::vector<double> s(x.size()), u(x.size());
  for (std::size_t i = 0; i < x.size(); ++i) {
    // peak at 0.3 L: asymmetric, so no two samples tie for an extreme deviation
    s[i] = h * (x[i] < 0.3 * L ? x[i] / (0.3 * L) : (L - x[i]) / (0.7 * L)) + 0.01 * x[i];
    u[i] = 0.01 + 0.00004 * x[i];  // 0.01 .. 0.03 um, well below the 0.11 um step of the tent
  }
  std::mt19937 rng(11);
  std::normal_distribution<double> nd(0, 1);
  EvaluationOptions uncorr;
  uncorr.correlation = Correlation::uncorrelated;
  for (const auto ref : kAllLines) {
    INFO(to_string(ref));
    const auto r = evaluate_straightness(x, s, u, ref, uncorr);
    double sum = 0, sum_x = 0;
    for (std::size_t i = 0; i < x.size(); ++i)
      sum += r.sensitivity[i], sum_x += r.sensitivity[i] * x[i];
    CHECK(sum == Approx(0).margin(1e-12));
    CHECK(sum_x == Approx(0).margin(1e-9));
    CHECK(r.uncertainty.expanded == Approx(2 * r.uncertainty.u_uncorrelated));
    CHECK(r.uncertainty.u_bound >= r.uncertainty.u_uncorrelated);
    const int draws = 4000;
    double m1 = 0, m2 = 0;
    std::vector<double> sp(s.size());
    for (int d = 0; d < draws; ++d) {
      for (std::size_t i = 0; i < s.size(); ++i)
        sp[i] = s[i] + u[i] * nd(rng);
      const double t = evaluate_straightness(x, sp, {}, ref).straightness_um;
      m1 += t;
      m2 += t * t;
    }
    const double mean = m1 / draws;
    const double sd = std::sqrt(m2 / draws - mean * mean);
    CHECK(sd == Approx(r.uncertainty.u_uncorrelated).epsilon(0.05));
  }
  // Full covariance: diagonal gives the uncorrelated value, perfect correlation of equal u gives 0
  // (a common offset does not change a straightness).
  const auto r = evaluate_straightness(x, s, u, ReferenceLine::least_squares);
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(101, 101);
  for (int i = 0; i < 101; ++i)
    cov(i, i) = u[static_cast<std::size_t>(i)] * u[static_cast<std::size_t>(i)];
  CHECK(propagate_covariance(r.sensitivity, cov) == Approx(r.uncertainty.u_uncorrelated));
  CHECK(propagate_covariance(r.sensitivity, Eigen::MatrixXd::Constant(101, 101, 0.04)) ==
        Approx(0).margin(1e-9));
}

TEST_CASE("local straightness of a parabola is h (l/L)^2 for every window and method") {
  const double L = 1000, h = 20, l = 250;
  const auto x = grid(0, L, 201);
  std::vector<double> s(x.size());
  for (std::size_t i = 0; i < x.size(); ++i)
    s[i] = 4 * h * (x[i] / L) * (1 - x[i] / L);
  for (const auto ref : kAllLines) {
    INFO(to_string(ref));
    const auto r = evaluate_local_straightness(x, s, {}, l, ref);
    CHECK(r.straightness_um == Approx(h * (l / L) * (l / L)).epsilon(1e-9));
    CHECK(r.windows == 151);  // starts 0, 5, ..., 750 mm
    CHECK(r.window_end_mm - r.window_start_mm == Approx(l));
  }
  // Local length = whole travel reproduces the global figure.
  CHECK(evaluate_local_straightness(x, s, {}, L, ReferenceLine::end_points).straightness_um ==
        Approx(h));
  CHECK_THROWS_AS(evaluate_local_straightness(x, s, {}, L + 1, ReferenceLine::end_points),
                  std::invalid_argument);
}

TEST_CASE("local straightness over one period of a multi-period sine") {
  const double period = 50, A = 1.5;
  const auto x = grid(0, 10 * period, 2001);
  std::vector<double> s(x.size());
  for (std::size_t i = 0; i < x.size(); ++i)
    s[i] = A * std::sin(2 * kPi * x[i] / period);
  const auto loc = evaluate_local_straightness(x, s, {}, period, ReferenceLine::minimum_zone);
  const auto all = evaluate_straightness(x, s, {}, ReferenceLine::minimum_zone);
  CHECK(all.straightness_um == Approx(2 * A).epsilon(1e-9));
  // The worst one-period window is the one starting at a zero crossing (the closed-form case)
  // or any other phase; none can be narrower than the one-period minimum zone of 1.3647 A
  // and none wider than 2A.
  CHECK(loc.straightness_um >= sine_minimum_zone_width() * A * (1 - 1e-5));
  CHECK(loc.straightness_um <= 2 * A + 1e-9);
}

TEST_CASE("angular deviation in urad and arcsec with uncertainty") {
  std::vector<double> g_urad = {1.0, 4.0, -2.5, 0.5, 3.0};
  std::vector<double> u = {0.1, 0.3, 0.4, 0.1, 0.1};
  EvaluationOptions uncorr;
  uncorr.correlation = Correlation::uncorrelated;
  const auto r = evaluate_angular_deviation(g_urad, u, uncorr);
  CHECK(r.deviation_urad == Approx(6.5));
  CHECK(r.deviation_arcsec == Approx(6.5 * 0.206264806).epsilon(1e-8));
  CHECK(r.index_max == 1);
  CHECK(r.index_min == 2);
  CHECK(r.uncertainty.u_uncorrelated == Approx(0.5));  // sqrt(0.3^2 + 0.4^2)
  CHECK(r.uncertainty.u_bound == Approx(0.7));
  CHECK(r.uncertainty.expanded == Approx(1.0));
  CHECK(r.expanded_uncertainty_arcsec == Approx(0.206264806).epsilon(1e-8));
  // 1 degree = 17453.29 urad = 3600 arcsec
  CHECK(kUradPerDeg * kArcsecPerUrad == Approx(3600.0));
}

TEST_CASE("flatness: tilted plane is flat, saddle is 2k for both planes") {
  std::vector<double> x, y, plane, saddle;
  const double k = 5.0;
  for (int i = -10; i <= 10; ++i)
    for (int j = -6; j <= 6; ++j) {
      const double xi = 20.0 * i, yj = 15.0 * j;
      x.push_back(xi);
      y.push_back(yj);
      plane.push_back(2.0 + 0.01 * xi - 0.03 * yj);
      // k x y normalised to [-1, 1]^2, plus a tilt that both methods must remove
      saddle.push_back(k * (xi / 200.0) * (yj / 90.0) + 0.02 * xi + 0.05 * yj - 7);
    }
  for (const auto ref : {ReferencePlane::least_squares, ReferencePlane::minimum_zone}) {
    INFO(to_string(ref));
    const auto p = evaluate_flatness(x, y, plane, {}, ref);
    CHECK(p.flatness_um == Approx(0).margin(1e-10));
    CHECK(p.plane.slope_x_um_per_mm == Approx(0.01).margin(1e-12));
    CHECK(p.plane.slope_y_um_per_mm == Approx(-0.03).margin(1e-12));
    CHECK(p.converged);
    // Saddle: the least-squares plane is the tilt (xy is orthogonal to 1, x, y on a symmetric
    // grid), range 2k; no plane does better, because the corner values of any plane satisfy
    // p(1,1) + p(-1,-1) - p(1,-1) - p(-1,1) = 0 while the saddle's give 4k.
    const auto s = evaluate_flatness(x, y, saddle, {}, ref);
    CHECK(s.flatness_um == Approx(2 * k).epsilon(1e-10));
    CHECK(s.converged);
  }
}

TEST_CASE("flatness: a sine ridge has the straightness figures of the sine, minimum zone < LS") {
  const double L = 400, A = 2.0;
  const auto xs = grid(0, L, 401);
  std::vector<double> x, y, w;
  for (double xi : xs)
    for (int j = 0; j < 5; ++j) {
      x.push_back(xi);
      y.push_back(25.0 * j);
      w.push_back(A * std::sin(2 * kPi * xi / L) + 0.004 * xi - 0.01 * 25.0 * j);
    }
  const auto ls = evaluate_flatness(x, y, w, {}, ReferencePlane::least_squares);
  const auto mz = evaluate_flatness(x, y, w, {}, ReferencePlane::minimum_zone);
  // Least squares: the x slope of a product grid is the 1-D slope (see the sine test above).
  const double M = 400, N = 401, h = L / M;
  const double b = -6 * A * M / std::tan(kPi / M) / (N * (N * N - 1) * h);
  CHECK(ls.flatness_um == Approx(-b * L).epsilon(1e-10));
  CHECK(ls.plane.slope_x_um_per_mm == Approx(b + 0.004).epsilon(1e-10));
  // Minimum zone: 401 samples per period move the interior extreme by < A (2 pi/400)^2 / 8.
  CHECK(mz.flatness_um == Approx(sine_minimum_zone_width() * A).epsilon(3e-4));
  CHECK(mz.converged);
}

TEST_CASE("minimum-zone plane is a minimum of the convex zone width (random clouds)") {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> ud(-50, 50);
  std::normal_distribution<double> nd(0, 1);
  for (int trial = 0; trial < 10; ++trial) {
    const std::size_t n = 10 + 15 * static_cast<std::size_t>(trial);
    std::vector<double> x(n), y(n), w(n);
    for (std::size_t i = 0; i < n; ++i) {
      x[i] = ud(rng);
      y[i] = ud(rng);
      w[i] = nd(rng) + 0.02 * x[i] * x[i] / 50;
    }
    const auto mz = evaluate_flatness(x, y, w, {}, ReferencePlane::minimum_zone);
    const auto ls = evaluate_flatness(x, y, w, {}, ReferencePlane::least_squares);
    REQUIRE(mz.converged);
    CHECK(mz.flatness_um <= ls.flatness_um + 1e-12);
    auto width = [&](double bx, double by) {
      double mx = -1e300, mn = 1e300;
      for (std::size_t i = 0; i < n; ++i) {
        const double r = w[i] - bx * x[i] - by * y[i];
        mx = std::max(mx, r);
        mn = std::min(mn, r);
      }
      return mx - mn;
    };
    const double bx = mz.plane.slope_x_um_per_mm, by = mz.plane.slope_y_um_per_mm;
    CHECK(width(bx, by) == Approx(mz.flatness_um).epsilon(1e-10));
    // A convex function with no descent direction at a point is minimal there.
    for (int dir = 0; dir < 64; ++dir) {
      const double a = 2 * kPi * dir / 64;
      for (const double step : {1e-6, 1e-4, 1e-2}) {
        REQUIRE(width(bx + step * std::cos(a), by + step * std::sin(a)) >= mz.flatness_um - 1e-10);
      }
    }
    // Sensitivity of a flatness: invariant to adding a plane.
    double s0 = 0, sx = 0, sy = 0;
    for (std::size_t i = 0; i < n; ++i) {
      s0 += mz.sensitivity[i];
      sx += mz.sensitivity[i] * x[i];
      sy += mz.sensitivity[i] * y[i];
    }
    CHECK(s0 == Approx(0).margin(1e-9));
    CHECK(sx == Approx(0).margin(1e-7));
    CHECK(sy == Approx(0).margin(1e-7));
  }
}

TEST_CASE("ISO 230-1 error symbols") {
  CHECK(straightness_symbol('X', 'Y') == "EYX");
  CHECK(straightness_symbol('x', 'z') == "EZX");
  CHECK(straightness_symbol('Y', 'X') == "EXY");
  CHECK(angular_symbol('X', 'Y') == "ECX");
  CHECK(angular_symbol('X', 'Z') == "EBX");
  CHECK(angular_symbol('Y', 'X') == "ECY");
  CHECK(angular_symbol('Z', 'Y') == "EAZ");
  CHECK(positioning_symbol('X') == "EXX");
  CHECK_THROWS_AS(straightness_symbol('X', 'X'), std::invalid_argument);
  CHECK_THROWS_AS(angular_symbol('Q', 'X'), std::invalid_argument);
}

TEST_CASE("flatness of three points is zero for both planes") {
  for (const auto ref : {ReferencePlane::least_squares, ReferencePlane::minimum_zone}) {
    const auto r = evaluate_flatness({0, 10, 0}, {0, 0, 10}, {1, 2, 5}, {}, ref);
    CHECK(r.flatness_um == Approx(0).margin(1e-12));
    CHECK(r.plane.at(10, 10) == Approx(6));
  }
}

TEST_CASE("bad input is rejected with a message") {
  CHECK_THROWS_WITH(evaluate_straightness({0, 1, 1}, {0, 0, 0}, {}, ReferenceLine::end_points),
                    Catch::Contains("strictly increasing"));
  CHECK_THROWS_WITH(evaluate_straightness({0, 1}, {0}, {}, ReferenceLine::end_points),
                    Catch::Contains("2 positions but 1 values"));
  CHECK_THROWS_WITH(
      evaluate_flatness({0, 1, 2}, {0, 1, 2}, {0, 0, 1}, {}, ReferencePlane::minimum_zone),
      Catch::Contains("one line"));
}

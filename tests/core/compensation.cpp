// Compensation tables: sign convention, coverage of the travel, and the optimal lincurve points.
#include "errsep/core/compensation.hpp"

#include <catch2/catch.hpp>
#include <cmath>
#include <random>
#include <vector>

using namespace errsep::core;

namespace {

constexpr double kPi = 3.14159265358979323846;

// Zhao et al. 2019 Eq. (21): S(x) in um over the travel L = 305 mm, sampled every 5 mm.
void zhao_s(std::vector<double>* x, std::vector<double>* s, double step = 5.0) {
  const double L = 305;
  x->clear();
  s->clear();
  for (double xi = 0; xi <= L + 1e-9; xi += step) {
    x->push_back(xi);
    s->push_back(8.075 * std::sin(4 * kPi / L * xi) +
                 5.7 * std::sin(6 * kPi / L * xi + 5 * kPi / 18) -
                 1.9 * std::sin(14 * kPi / L * xi + kPi / 2));
  }
}

double range(const std::vector<double>& v) {
  return *std::max_element(v.begin(), v.end()) - *std::min_element(v.begin(), v.end());
}

}  // namespace

TEST_CASE("compensation = -error: commanded + comp + error = commanded at the table nodes") {
  std::vector<double> x, s;
  zhao_s(&x, &s);
  CompensationOptions opts;
  opts.step_mm = 5;
  opts.remove_line.reset();  // keep S as measured
  const auto t = make_uniform_table(x, s, opts);
  REQUIRE(t.comp_um.size() == x.size());  // same grid: nodes are the samples
  for (std::size_t i = 0; i < x.size(); ++i)
    CHECK(t.comp_um[i] + s[i] == Approx(0).margin(1e-12));
  CHECK(t.max_interpolation_error_um == Approx(0).margin(1e-12));
  // error_sign = -1 flips the table.
  opts.error_sign = -1;
  const auto f = make_uniform_table(x, s, opts);
  for (std::size_t i = 0; i < x.size(); ++i)
    CHECK(f.comp_um[i] == Approx(s[i]).margin(1e-12));
}

TEST_CASE("the end-point line is removed by default and the table covers the whole travel") {
  std::vector<double> x, s;
  zhao_s(&x, &s);
  for (std::size_t i = 0; i < x.size(); ++i)
    s[i] += 1.5 + 0.02 * x[i];  // alignment tilt
  CompensationOptions opts;
  opts.step_mm = 20;  // 305 / 20 = 15.25 -> 17 nodes, 0 .. 320 mm
  const auto t = make_uniform_table(x, s, opts);
  CHECK(t.comp_um.size() == 17);
  CHECK(t.start_mm == 0);
  CHECK(t.end_mm() == Approx(320));
  CHECK(t.comp_um.front() == Approx(0).margin(1e-12));  // end points on the removed line
  CHECK(t.comp_um.back() == Approx(0).margin(1e-12));   // held end value beyond 305 mm
  const auto e = error_to_compensate(x, s, opts);
  CHECK(e.front() == Approx(0).margin(1e-12));
  CHECK(e.back() == Approx(0).margin(1e-12));
  // max_points is enforced with an actionable message.
  opts.max_points = 10;
  CHECK_THROWS_WITH(make_uniform_table(x, s, opts), Catch::Contains("exceed the limit of 10") &&
                                                        Catch::Contains("use a step of at least"));
  opts.max_points = 0;
  opts.step_mm = 0;
  CHECK_THROWS_WITH(make_uniform_table(x, s, opts), Catch::Contains("step_mm"));
}

TEST_CASE("interpolate_hold holds the end values outside the table") {
  const std::vector<double> xs = {0, 10, 30}, ys = {1, 3, -1};
  CHECK(interpolate_hold(xs, ys, -5) == 1);
  CHECK(interpolate_hold(xs, ys, 5) == Approx(2));
  CHECK(interpolate_hold(xs, ys, 20) == Approx(1));
  CHECK(interpolate_hold(xs, ys, 30) == -1);
  CHECK(interpolate_hold(xs, ys, 99) == -1);
}

TEST_CASE("breakpoint selection is optimal among sample breakpoints (brute force, small N)") {
  std::mt19937 rng(5);
  std::normal_distribution<double> nd(0, 1);
  CompensationOptions opts;
  opts.remove_line.reset();
  for (int trial = 0; trial < 30; ++trial) {
    const std::size_t n = 9 + static_cast<std::size_t>(trial % 5);
    std::vector<double> x(n), s(n);
    double xi = 0;
    for (std::size_t i = 0; i < n; ++i) {
      xi += 1 + std::abs(nd(rng));  // uneven spacing
      x[i] = xi;
      s[i] = nd(rng) * 3;
    }
    BreakpointOptions b;
    b.max_points = 4 + static_cast<std::size_t>(trial % 3);  // 4..6 of 9..13 samples
    const auto t = make_breakpoint_table(x, s, opts, b);
    REQUIRE(t.x_mm.size() <= b.max_points);
    CHECK(t.x_mm.front() == x.front());
    CHECK(t.x_mm.back() == x.back());
    // Brute force over every subset of interior samples of size <= max_points - 2.
    double best = 1e300;
    const std::size_t interior = n - 2;
    for (std::uint32_t mask = 0; mask < (1u << interior); ++mask) {
      if (static_cast<std::size_t>(__builtin_popcount(mask)) > b.max_points - 2) continue;
      std::vector<double> bx = {x[0]}, by = {-s[0]};
      for (std::size_t k = 0; k < interior; ++k)
        if (mask & (1u << k)) bx.push_back(x[k + 1]), by.push_back(-s[k + 1]);
      bx.push_back(x[n - 1]);
      by.push_back(-s[n - 1]);
      double err = 0;
      for (std::size_t i = 0; i < n; ++i)
        err = std::max(err, std::abs(interpolate_hold(bx, by, x[i]) + s[i]));
      best = std::min(best, err);
    }
    CHECK(t.max_interpolation_error_um == Approx(best).epsilon(1e-9));
    // The reported error is the real one.
    double err = 0;
    for (std::size_t i = 0; i < n; ++i)
      err = std::max(err, std::abs(interpolate_hold(t.x_mm, t.comp_um, x[i]) + s[i]));
    CHECK(err == Approx(t.max_interpolation_error_um).epsilon(1e-12));
  }
}

TEST_CASE("16 lincurve points on the Zhao 2019 Eq. (21) slideway") {
  // 305 mm travel sampled every 1 mm (306 samples; every sample is a candidate).
  std::vector<double> x, s;
  zhao_s(&x, &s, 1.0);
  CompensationOptions opts;
  const auto t = make_breakpoint_table(x, s, opts);
  REQUIRE(t.x_mm.size() <= 16);
  const auto e = error_to_compensate(x, s, opts);
  const double original = range(e);
  // Residual after compensation (what the machine would still show), computed independently.
  std::vector<double> res(x.size());
  for (std::size_t i = 0; i < x.size(); ++i)
    res[i] = e[i] + interpolate_hold(t.x_mm, t.comp_um, x[i]);
  double max_abs = 0;
  for (double r : res)
    max_abs = std::max(max_abs, std::abs(r));
  CHECK(max_abs == Approx(t.max_interpolation_error_um).epsilon(1e-12));
  WARN("lincurve 16 points on Eq. (21): straightness "
       << original << " um, max interpolation error " << t.max_interpolation_error_um << " um, rms "
       << t.rms_interpolation_error_um << " um");
  // Stated target: the residual straightness is below 10 % of the original.
  CHECK(range(res) < 0.10 * original);
  // Uniform spacing with the same 16 points is never better than the optimised choice.
  std::vector<double> ux, uy;
  for (int k = 0; k < 16; ++k) {
    const double xi = 305.0 * k / 15;
    ux.push_back(xi);
    uy.push_back(-interpolate_hold(x, e, xi));
  }
  double uniform_err = 0;
  for (std::size_t i = 0; i < x.size(); ++i)
    uniform_err = std::max(uniform_err, std::abs(interpolate_hold(ux, uy, x[i]) + e[i]));
  CHECK(t.max_interpolation_error_um <= uniform_err);
}

TEST_CASE("breakpoint selection on a long noisy scan uses a candidate subset and stays fast") {
  std::mt19937 rng(9);
  std::normal_distribution<double> nd(0, 0.05);
  std::vector<double> x, s;
  zhao_s(&x, &s, 0.05);  // 6101 samples
  for (auto& v : s)
    v += nd(rng);
  const auto t = make_breakpoint_table(x, s, {});
  CHECK(t.candidates <= 600);
  CHECK(t.x_mm.size() <= 16);
  CHECK(t.max_interpolation_error_um < 0.1 * range(error_to_compensate(x, s, {})));
}

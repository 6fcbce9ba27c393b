// Recorded scan-1 times against the declared two-axis plan (core/displacement_scan1_times.hpp):
// the finding the app words (tests/apps/displacement_app.cpp checks the message).
#include <algorithm>
#include <catch2/catch.hpp>
#include <vector>

#include "errsep/core/displacement_scan1_times.hpp"

using namespace errsep::core;

namespace {

Eigen::MatrixXd times(Scan1Order o, int nx, int ny, double period_s = 0.5) {
  Eigen::MatrixXd t(nx, ny);
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i)
      t(i, j) = 3.0 + period_s * scan1_reading_index(o, i, j, nx, ny);
  return t;
}

}  // namespace

TEST_CASE("scan-1 times: each plan's times pass its declaration and name it under the other") {
  constexpr int nx = 6, ny = 5;
  TwoAxisScanOrder raster, diagonal;
  diagonal.diagonal_scan1 = true;
  // Every index once per order.
  for (const Scan1Order o :
       {Scan1Order::raster_x_fastest, Scan1Order::diagonal, Scan1Order::raster_y_fastest}) {
    std::vector<int> seen(nx * ny, 0);
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        ++seen[static_cast<std::size_t>(scan1_reading_index(o, i, j, nx, ny))];
    CHECK(std::count(seen.begin(), seen.end(), 1) == nx * ny);
  }
  CHECK(check_scan1_times(Eigen::MatrixXd(), raster).consistent);
  CHECK(check_scan1_times(times(Scan1Order::raster_x_fastest, nx, ny), raster).consistent);
  CHECK(check_scan1_times(times(Scan1Order::diagonal, nx, ny), diagonal).consistent);

  // Diagonal times declared raster: the first pair out of order is consecutive in the raster.
  const auto d = check_scan1_times(times(Scan1Order::diagonal, nx, ny), raster);
  CHECK_FALSE(d.consistent);
  CHECK(d.declared == Scan1Order::raster_x_fastest);
  REQUIRE(d.recorded.has_value());
  CHECK(*d.recorded == Scan1Order::diagonal);
  CHECK(d.t0_s >= d.t1_s);
  CHECK(scan1_reading_index(Scan1Order::raster_x_fastest, d.i1, d.j1, nx, ny) ==
        scan1_reading_index(Scan1Order::raster_x_fastest, d.i0, d.j0, nx, ny) + 1);

  const auto r = check_scan1_times(times(Scan1Order::raster_x_fastest, nx, ny), diagonal);
  CHECK_FALSE(r.consistent);
  REQUIRE(r.recorded.has_value());
  CHECK(*r.recorded == Scan1Order::raster_x_fastest);
  // The diagonal reads (0, 0) then (1, 1): the raster has them at 3.0 s and 3.0 + 0.5·7 s, in
  // order; then (2, 2) at raster index 14, (3, 3) 21, (4, 4) 28, (5, 0) 5: the first inversion.
  CHECK(r.i0 == 4);
  CHECK(r.j0 == 4);
  CHECK(r.i1 == 5);
  CHECK(r.j1 == 0);
  CHECK(r.t0_s == Approx(3.0 + 0.5 * 28));
  CHECK(r.t1_s == Approx(3.0 + 0.5 * 5));

  for (const TwoAxisScanOrder& o : {raster, diagonal}) {
    const auto y = check_scan1_times(times(Scan1Order::raster_y_fastest, nx, ny), o);
    CHECK_FALSE(y.consistent);
    REQUIRE(y.recorded.has_value());
    CHECK(*y.recorded == Scan1Order::raster_y_fastest);
  }
  // Times of no plan (one reading repeated in time): no order named.
  Eigen::MatrixXd flat = times(Scan1Order::raster_x_fastest, nx, ny);
  flat(3, 2) = flat(0, 0);
  for (const TwoAxisScanOrder& o : {raster, diagonal}) {
    const auto n = check_scan1_times(flat, o);
    CHECK_FALSE(n.consistent);
    CHECK_FALSE(n.recorded.has_value());
  }
}

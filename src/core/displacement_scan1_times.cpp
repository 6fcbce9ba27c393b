#include "errsep/core/displacement_scan1_times.hpp"

#include <cmath>
#include <utility>
#include <vector>

namespace errsep::core {
namespace {

struct Inversion {
  int i0, j0, i1, j1;
};

/// The first pair of grid points whose times do not increase along the order; nullopt if none.
std::optional<Inversion> first_inversion(const Eigen::MatrixXd& t, Scan1Order order) {
  const int nx = static_cast<int>(t.rows()), ny = static_cast<int>(t.cols());
  std::vector<std::pair<int, int>> at(static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny),
                                      {-1, -1});
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i)
      at[static_cast<std::size_t>(scan1_reading_index(order, i, j, nx, ny))] = {i, j};
  for (std::size_t k = 1; k < at.size(); ++k) {
    const auto [i0, j0] = at[k - 1];
    const auto [i1, j1] = at[k];
    if (!(t(i1, j1) > t(i0, j0))) return Inversion{i0, j0, i1, j1};
  }
  return std::nullopt;
}

}  // namespace

int scan1_reading_index(Scan1Order order, int i, int j, int nx, int ny) {
  if (order == Scan1Order::raster_y_fastest) return i * ny + j;
  TwoAxisScanOrder o;  // one second per reading: the index
  o.diagonal_scan1 = order == Scan1Order::diagonal;
  return static_cast<int>(std::lround(o.time_s(1, i, j, nx, ny)));
}

Scan1TimesFinding check_scan1_times(const Eigen::MatrixXd& t, const TwoAxisScanOrder& declared) {
  Scan1TimesFinding f;
  f.declared = declared.diagonal_scan1 ? Scan1Order::diagonal : Scan1Order::raster_x_fastest;
  if (t.size() == 0) return f;
  const auto bad = first_inversion(t, f.declared);
  if (!bad) return f;
  f.consistent = false;
  f.i0 = bad->i0, f.j0 = bad->j0, f.i1 = bad->i1, f.j1 = bad->j1;
  f.t0_s = t(bad->i0, bad->j0);
  f.t1_s = t(bad->i1, bad->j1);
  const Scan1Order other =
      declared.diagonal_scan1 ? Scan1Order::raster_x_fastest : Scan1Order::diagonal;
  if (!first_inversion(t, other))
    f.recorded = other;
  else if (!first_inversion(t, Scan1Order::raster_y_fastest))
    f.recorded = Scan1Order::raster_y_fastest;
  return f;
}

}  // namespace errsep::core

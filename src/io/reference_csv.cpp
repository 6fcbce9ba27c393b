#include "errsep/io/reference_csv.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "errsep/io/csv.hpp"

namespace errsep::io {

namespace {

std::size_t line_of(const CsvTable& t, std::size_t row) {
  return t.row_line.empty() ? 0 : t.row_line[row];
}

}  // namespace

ReferenceTrace read_reference_csv(const std::filesystem::path& file) {
  const CsvTable t = read_csv(file, {false, 2});
  ReferenceTrace out;
  out.x_mm = t.column("x_mm", file);
  if (t.find_column("S_um")) out.S_um = t.column("S_um", file);
  if (t.find_column("gamma_urad")) out.gamma_urad = t.column("gamma_urad", file);
  if (t.find_column("f_um")) out.f_um = t.column("f_um", file);
  if (!out.S_um && !out.gamma_urad && !out.f_um)
    throw CsvError(file, 0, "no profile column: need at least one of S_um, gamma_urad, f_um");
  for (std::size_t r = 1; r < out.x_mm.size(); ++r)
    if (!(out.x_mm[r] > out.x_mm[r - 1]))
      throw CsvError(file, line_of(t, r),
                     "x_mm = " + std::to_string(out.x_mm[r]) + " does not increase (previous row " +
                         std::to_string(out.x_mm[r - 1]) + ")");
  return out;
}

core::RefineTruth read_truth_csv(const std::filesystem::path& file,
                                 const core::FourSensorConfig& cfg, double x0_mm) {
  CsvReadOptions o;
  o.allow_non_finite = true;  // S and γ are absent beyond the slide positions
  const CsvTable t = read_csv(file, o);
  const std::vector<double> x = t.column("x_mm", file), f = t.column("f_um", file),
                            S = t.column("S_um", file), g = t.column("gamma_urad", file);
  const auto N = static_cast<std::size_t>(cfg.N), P = static_cast<std::size_t>(cfg.positions());
  if (x.size() < N)
    throw CsvError(file, 0,
                   std::to_string(x.size()) +
                       " rows; the scan's reference has N = " + std::to_string(N) + " points");
  core::RefineTruth truth;
  truth.f_um.resize(static_cast<Eigen::Index>(N));
  truth.S_um.resize(static_cast<Eigen::Index>(P));
  truth.gamma_rad.resize(static_cast<Eigen::Index>(P));
  for (std::size_t j = 0; j < N; ++j) {
    const double expect = x0_mm + static_cast<double>(j) * cfg.dx_mm;
    if (!std::isfinite(x[j]) || std::abs(x[j] - expect) > 1e-6 * std::max(1.0, cfg.dx_mm))
      throw CsvError(file, line_of(t, j),
                     "x_mm = " + std::to_string(x[j]) + ", expected " + std::to_string(expect) +
                         " (rows must follow the scan's dx = " + std::to_string(cfg.dx_mm) +
                         " mm grid from its first position)");
    if (!std::isfinite(f[j])) throw CsvError(file, line_of(t, j), "f_um is not a finite number");
    truth.f_um(static_cast<Eigen::Index>(j)) = f[j];
    if (j < P) {
      if (!std::isfinite(S[j]) || !std::isfinite(g[j]))
        throw CsvError(file, line_of(t, j),
                       "S_um and gamma_urad must be finite at the slide positions (first " +
                           std::to_string(P) + " rows)");
      truth.S_um(static_cast<Eigen::Index>(j)) = S[j];
      truth.gamma_rad(static_cast<Eigen::Index>(j)) = 1e-6 * g[j];
    }
  }
  return truth;
}

void write_truth_csv(const std::filesystem::path& file, const core::RefineTruth& truth,
                     const core::FourSensorConfig& cfg, double x0_mm,
                     const std::vector<std::pair<std::string, std::string>>& metadata) {
  const Eigen::Index N = cfg.N, P = cfg.positions();
  if (truth.f_um.size() != N || truth.S_um.size() != P || truth.gamma_rad.size() != P)
    throw std::invalid_argument(
        "truth of " + file.string() + ": " + std::to_string(truth.f_um.size()) + " f, " +
        std::to_string(truth.S_um.size()) + " S and " + std::to_string(truth.gamma_rad.size()) +
        " gamma values for N = " + std::to_string(N) + ", P = " + std::to_string(P));
  CsvTable t;
  t.metadata = metadata;
  t.set_meta("units", "x in mm, f and S in um, gamma in urad; S and gamma nan beyond the " +
                          std::to_string(P) + " slide positions");
  t.columns = {"x_mm", "f_um", "S_um", "gamma_urad"};
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (Eigen::Index j = 0; j < N; ++j)
    t.rows.push_back({x0_mm + static_cast<double>(j) * cfg.dx_mm, truth.f_um(j),
                      j < P ? truth.S_um(j) : nan, j < P ? 1e6 * truth.gamma_rad(j) : nan});
  write_csv(file, t, 15);
}

}  // namespace errsep::io

#include "errsep/io/four_sensor_inputs.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "errsep/io/csv.hpp"

namespace errsep::io {

namespace fs = std::filesystem;

FourSensorInputs four_sensor_inputs(const RawFourSensorScan& raw, const fs::path& file,
                                    const GeometryOverrides& geometry) {
  FourSensorInputs in;
  core::FourSensorConfig& cfg = in.cfg;
  if (raw.geometry) cfg = *raw.geometry;
  if (geometry.s2 > 0) cfg.s2 = geometry.s2;
  if (geometry.s3 > 0) cfg.s3 = geometry.s3;
  if (geometry.s4 > 0) cfg.s4 = geometry.s4;
  const auto P = static_cast<int>(raw.positions());
  if (P < 2) throw CsvError(file, 0, "need at least 2 slide positions, got " + std::to_string(P));
  if (geometry.dx_mm > 0)
    cfg.dx_mm = geometry.dx_mm;
  else if (!raw.geometry)
    cfg.dx_mm = raw.x_mm[1] - raw.x_mm[0];
  // The rows must lie on the Δx grid: x_n = x_0 + n·Δx (Eq. 5).
  for (int n = 0; n < P; ++n) {
    const double x = raw.x_mm[static_cast<std::size_t>(n)];
    const double expect = raw.x_mm[0] + n * cfg.dx_mm;
    if (!(std::abs(x - expect) <= 1e-6 * std::max(1.0, cfg.dx_mm)))
      throw CsvError(file, 0,
                     "x_mm of data row " + std::to_string(n + 1) + " is " + std::to_string(x) +
                         ", expected " + std::to_string(expect) +
                         " (rows must be on the dx = " + std::to_string(cfg.dx_mm) + " mm grid)");
  }
  cfg.N = P + cfg.s2 + cfg.s3 + cfg.s4;
  std::string why;
  if (!cfg.is_valid(&why))
    throw CsvError(file, 0, std::to_string(P) + " rows do not fit the spacing: " + why);
  in.x_mm.resize(P);
  in.m_um.resize(P, 4);
  for (int n = 0; n < P; ++n) {
    in.x_mm(n) = raw.x_mm[static_cast<std::size_t>(n)];
    for (int j = 0; j < 4; ++j) {
      const double v = raw.m_um[static_cast<std::size_t>(j)][static_cast<std::size_t>(n)];
      if (!std::isfinite(v))
        throw CsvError(file, 0,
                       "m" + std::to_string(j + 1) + "_um of data row " + std::to_string(n + 1) +
                           " is not a finite number");
      in.m_um(n, j) = v;
    }
  }
  if (raw.t_s) {
    in.t_s.resize(P, 4);
    for (int n = 0; n < P; ++n)
      for (int j = 0; j < 4; ++j) {
        const double v = (*raw.t_s)[static_cast<std::size_t>(j)][static_cast<std::size_t>(n)];
        if (!std::isfinite(v))
          throw CsvError(file, 0,
                         "t" + std::to_string(j + 1) + "_s of data row " + std::to_string(n + 1) +
                             " is not a finite number");
        in.t_s(n, j) = v;
      }
  }
  if (raw.sequence) {
    RawFourSensorScan r = raw;
    r.geometry = cfg;
    in.sequence = scan_sequence_of(r);
    if (!in.sequence->second.allFinite())
      throw CsvError(file, 0, "a traverse column (kK_um) holds a value that is not finite");
  }
  return in;
}

}  // namespace errsep::io

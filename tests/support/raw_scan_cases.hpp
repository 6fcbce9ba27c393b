#pragma once
// Raw four-sensor scans of random machines, as the scan runner records them, for the tests of
// what is made from a raw scan (the pipeline, the report after a scan).
#include <cstdint>
#include <string>

#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/io/raw_scan_csv.hpp"

namespace errsep::test {

/// A complete raw scan of a random smooth slideway (several harmonics, random phases and
/// amplitudes per seed), noise (0.1 um) on each reading.
inline io::RawFourSensorScan simulated_raw(std::uint64_t seed) {
  const core::FourSensorConfig cfg;
  core::FourSensorSimOptions so;
  so.sigma_um = 0.1;
  so.seed = seed;
  const auto sim = core::simulate_four_sensor(cfg, core::random_smooth_truth(cfg, seed), so);
  io::RawFourSensorScan raw;
  raw.complete = true;
  raw.geometry = cfg;
  raw.x_mm.assign(sim.x_mm.data(), sim.x_mm.data() + sim.x_mm.size());
  for (std::size_t j = 0; j < 4; ++j)
    for (Eigen::Index n = 0; n < sim.m_um.rows(); ++n)
      raw.m_um[j].push_back(sim.m_um(n, static_cast<Eigen::Index>(j)));
  raw.metadata = {{"scan_id", std::to_string(seed)}};
  return raw;
}

}  // namespace errsep::test

#pragma once
// What the tests that compare two result folders (errsep-daemon's and errsep-scan's) read of
// them, the files under a folder and the header line of a CSV, and the quick simulated machine
// they scan.
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include "support/support.hpp"

namespace errsep::test {

/// Every file under `dir`, as paths relative to it (sorted).
inline std::set<std::string> files_under(const std::filesystem::path& dir) {
  std::set<std::string> out;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir))
    if (e.is_regular_file()) out.insert(std::filesystem::relative(e.path(), dir).generic_string());
  return out;
}

/// RMS of a − b after removing its mean: how far two displacement-method profiles differ in
/// shape (their constant is the method's gauge).  Equal sizes expected.
inline double rms_shape(const std::vector<double>& a, const std::vector<double>& b) {
  double mean = 0;
  for (std::size_t k = 0; k < a.size(); ++k)
    mean += (a[k] - b[k]) / static_cast<double>(a.size());
  double s = 0;
  for (std::size_t k = 0; k < a.size(); ++k)
    s += (a[k] - b[k] - mean) * (a[k] - b[k] - mean);
  return a.empty() ? 0.0 : std::sqrt(s / static_cast<double>(a.size()));
}

/// The header line of an errsep CSV (the first line that is not a '#' metadata line).
inline std::string header_of(const std::filesystem::path& csv) {
  std::ifstream in(csv);
  std::string line;
  while (std::getline(in, line))
    if (!line.empty() && line[0] != '#') return line;
  return {};
}

/// Two result folders of the same kind of scan (the daemon's and errsep-scan's) hold the same
/// files, each a whole result set, and every CSV in both has the same (non-empty) header line.
/// Returns how many CSVs were compared.
int check_same_result_files(const std::filesystem::path& a, const std::filesystem::path& b);

/// errsep-report reads the result folder `dir` (exit 0; plots off, for speed).
void check_report_reads(const std::filesystem::path& dir);

/// The shipped simulator config (config/simulator.toml) with its stages 10-20 times faster, for
/// scans that take about a second.
inline std::string quick_simulator_config() {
  std::string t = read_file(source_dir() / "config" / "simulator.toml");
  for (const std::string from : {"speed_mm_s = 200.0", "speed_mm_s = 100.0"})
    for (auto pos = t.find(from); pos != std::string::npos; pos = t.find(from, pos))
      t.replace(pos, from.size(), "speed_mm_s = 2000.0");
  return t;
}

}  // namespace errsep::test

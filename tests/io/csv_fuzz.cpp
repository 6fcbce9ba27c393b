// A bounded, seeded mutation fuzz run of errsep's readers of input files (issue 21): valid files
// of every format, mutated (bytes changed, tokens such as nan, inf, 1e308, -8.7e10 or metadata
// lines inserted, spans deleted, lines duplicated or swapped, cut short), read by every reader.
// A reader may accept the input or refuse it with a CsvError ("file:line: problem"); anything else
// (another exception, a crash, a hang, a sanitizer report in the ASan+UBSan build of CI) fails.
// Accepted raw scans also pass through four_sensor_inputs, the last step before the solvers, and
// what a reader accepted must be plausible (finite readings within the bound).  The manifest
// reader of result sets is fuzzed the same way: it must report problems, never throw.
// 3000 inputs, about 2 s in the release build.
#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>
#include <typeinfo>

#include "errsep/io/atomic_file.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/displacement_csv.hpp"
#include "errsep/io/four_sensor_inputs.hpp"
#include "errsep/io/plausibility.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "errsep/io/reference_csv.hpp"
#include "errsep/io/staged_directory.hpp"
#include "support/support.hpp"

using namespace errsep;
namespace fs = std::filesystem;

namespace {

std::string raw_four_sensor() {
  io::RawFourSensorScan s;
  core::FourSensorConfig g;
  g.dx_mm = 5;
  g.s2 = 1;
  g.s3 = 1;
  g.s4 = 2;
  g.N = 12;  // P = 8
  s.geometry = g;
  s.complete = true;
  s.t_s.emplace();
  for (int n = 0; n < 8; ++n) {
    s.x_mm.push_back(5.0 * n);
    for (std::size_t i = 0; i < 4; ++i) {
      s.m_um[i].push_back(0.5 * std::sin(n + static_cast<double>(i)) + 0.1 * i);
      (*s.t_s)[i].push_back(10.0 * static_cast<double>(i) + 0.5 * n);
    }
  }
  s.metadata = {{"range_min_m1_um", "-2000"}, {"range_max_m1_um", "2000"}};
  return io::format_csv(io::to_csv_table(s), 12);
}

std::string raw_displacement() {
  io::RawDisplacementScan s;
  for (int n = 0; n < 6; ++n) {
    s.x_mm.push_back(5.0 * n);
    s.s1_scan1_um.push_back(0.3 * n);
    s.s2_scan1_um.push_back(0.2 * n - 1);
    s.s1_scan2_um.push_back(0.3 * n + 0.01);
    s.s2_scan2_um.push_back(0.2 * n - 0.8);
  }
  s.t_scan1_s = std::vector<double>{0, 1, 2, 3, 4, 5};
  s.t_scan2_s = std::vector<double>{6, 7, 8, 9, 10, 11};
  s.d_mm = 5;
  s.complete = true;
  s.metadata = {{"range_min_s1_um", "-100"}, {"range_max_s1_um", "100"}};
  return io::format_csv(io::to_csv_table(s), 12);
}

std::string two_axis() {
  std::ostringstream os;
  os << "x_mm,y_mm,s0_scan1_um,s1_scan1_um,s1_scan2_um,s2_scan1_um,s2_scan2_um,s3_scan1_um,"
        "s3_scan2_um,s4_scan1_um,s4_scan2_um,t_scan1_s\n";
  int k = 0;
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i, ++k) {
      os << 5 * i << "," << 5 * j;
      for (int c = 0; c < 9; ++c)
        os << "," << 0.1 * (i + 2 * j + c);
      os << "," << k << "\n";
    }
  return os.str();
}

std::string three_point() {
  return "# d: 5\nx_mm,m1_um,m2_um,m3_um\n0,0.1,0.2,0.3\n5,0.2,0.1,0.0\n10,0.3,0.3,0.1\n"
         "15,0.0,0.2,0.2\n";
}

std::string reference() {
  return "x_mm,S_um,gamma_urad\n0,0.1,1\n5,0.2,2\n10,0.15,1.5\n15,0.0,0.5\n";
}

std::string manifest() {
  return "# errsep result set\nkind: scan\nrun_id: 20261125T000000Z-1-abcd\nwriter: t\n"
         "created_utc: 2026-11-25T00:00:00Z\nentries: 2\nfile 5 2ad4d5c2 a.csv\n"
         "set 20261125T000000Z-2-abcd refine/\nend\n";
}

const std::vector<std::string> kTokens = {"nan",
                                          "inf",
                                          "-inf",
                                          "1e308",
                                          "-1e308",
                                          "1e999",
                                          "-8.7e10",
                                          "1e-320",
                                          "0x1p3",
                                          "+",
                                          "-",
                                          ".",
                                          "e",
                                          ",",
                                          ",,",
                                          "\n",
                                          "\r\n",
                                          "\t",
                                          " ",
                                          "#",
                                          ":",
                                          "\"",
                                          "0",
                                          "-0",
                                          "99999999999999999999",
                                          "x_mm",
                                          "m1_um",
                                          "t1_s",
                                          "# complete: false\n",
                                          "# complete: true\n",
                                          "# dx_mm: 0\n",
                                          "# N: -3\n",
                                          "# s2: 2147483648\n",
                                          "# range_min_m1_um: 5\n",
                                          "# range_max_m1_um: -5\n",
                                          "# range_min_s1_um: nan\n",
                                          "# d_mm: inf\n",
                                          "# format: errsep raw four-sensor scan\n",
                                          "file 1 0 ../x\n",
                                          "set - /\n",
                                          "entries: 99999999999999999999\n",
                                          "end\n"};

std::string mutate(std::string s, std::mt19937& rng) {
  auto pick = [&](std::size_t n) {
    return n == 0 ? std::size_t{0} : std::uniform_int_distribution<std::size_t>(0, n - 1)(rng);
  };
  const int rounds = 1 + static_cast<int>(pick(4));
  for (int r = 0; r < rounds; ++r) {
    switch (pick(7)) {
      case 0:  // change a byte
        if (!s.empty()) s[pick(s.size())] = static_cast<char>(pick(256));
        break;
      case 1:  // insert a token
        s.insert(pick(s.size() + 1), kTokens[pick(kTokens.size())]);
        break;
      case 2:  // replace a number-looking span by a token
      {
        const std::size_t at = pick(s.size() + 1);
        const std::size_t len = std::min<std::size_t>(pick(8), s.size() - std::min(at, s.size()));
        s.replace(std::min(at, s.size()), len, kTokens[pick(kTokens.size())]);
        break;
      }
      case 3:  // delete a span
        if (!s.empty()) {
          const std::size_t at = pick(s.size());
          s.erase(at, pick(16) + 1);
        }
        break;
      case 4:  // duplicate a line
      case 5:  // swap two lines
      {
        std::vector<std::string> lines;
        std::istringstream is(s);
        std::string l;
        while (std::getline(is, l))
          lines.push_back(l);
        if (lines.size() < 2) break;
        const std::size_t a = pick(lines.size()), b = pick(lines.size());
        if (r % 2 == 0)
          lines.insert(lines.begin() + static_cast<std::ptrdiff_t>(a), lines[b]);
        else
          std::swap(lines[a], lines[b]);
        s.clear();
        for (const auto& x : lines)
          s += x + "\n";
        break;
      }
      default:  // cut short
        s.resize(pick(s.size() + 1));
        break;
    }
  }
  return s;
}

/// Runs `read`; returns "" when it accepted or refused with a CsvError, else what went wrong.
std::string outcome(const std::function<void()>& read) {
  try {
    read();
  } catch (const io::CsvError&) {
  } catch (const std::exception& e) {
    return std::string("threw ") + typeid(e).name() + ": " + e.what();
  } catch (...) {
    return "threw a non-std exception";
  }
  return {};
}

void plausible(const std::vector<double>& v, bool allow_nan, const char* what) {
  for (double x : v)
    if (!(allow_nan && std::isnan(x)) &&
        !(std::isfinite(x) && std::abs(x) <= io::kMaxPlausibleReadingUm))
      throw std::logic_error(std::string("accepted an implausible ") + what + " " +
                             std::to_string(x));
}

}  // namespace

TEST_CASE("fuzz: 3000 mutated inputs, every reader accepts or refuses with file:line") {
  test::TempDir tmp;
  const fs::path f = tmp / "in.csv";
  core::FourSensorConfig cfg;
  cfg.dx_mm = 5;
  cfg.s2 = 1;
  cfg.s3 = 1;
  cfg.s4 = 2;
  cfg.N = 12;
  io::RawReadOptions inspect;
  inspect.require_complete = false;
  const std::vector<std::function<void()>> readers = {
      [&] { (void)io::read_csv(f); },
      [&] {
        const auto raw = io::read_raw_four_sensor_csv(f);
        for (const auto& m : raw.m_um)
          plausible(m, false, "reading");
        (void)io::four_sensor_inputs(raw, f);
      },
      [&] {
        const auto raw = io::read_raw_four_sensor_csv(f, inspect);
        for (const auto& m : raw.m_um)
          plausible(m, true, "reading");
      },
      [&] {
        const auto raw = io::read_raw_displacement_csv(f);
        plausible(raw.s1_scan1_um, false, "reading");
        plausible(raw.s2_scan2_um, false, "reading");
      },
      [&] { (void)io::read_one_axis_csv(f); },
      [&] { (void)io::read_two_axis_csv(f); },
      [&] { (void)io::read_three_point_csv(f); },
      [&] { (void)io::read_reference_csv(f); },
      [&] { (void)io::read_truth_csv(f, cfg, 0.0); },
  };
  const std::vector<std::string> seeds = {raw_four_sensor(), raw_displacement(), two_axis(),
                                          three_point(), reference()};
  std::mt19937 rng(21);
  int inputs = 0, accepted = 0, refused = 0;
  std::vector<std::string> failures;
  const int kInputs = 3000;
  for (int i = 0; i < kInputs; ++i) {
    const std::string text = mutate(seeds[static_cast<std::size_t>(i) % seeds.size()], rng);
    std::ofstream(f, std::ios::binary | std::ios::trunc) << text;  // no fsync: 3000 files
    ++inputs;
    for (std::size_t r = 0; r < readers.size(); ++r) {
      bool ok = true;
      const std::string why = outcome([&] {
        try {
          readers[r]();
        } catch (const io::CsvError& e) {
          ok = false;
          // "file:line: problem" (line 0 = the whole file: "file: problem")
          if (std::string(e.what()).rfind(f.string() + ":", 0) != 0)
            throw std::logic_error(std::string("a CsvError not naming the file: ") + e.what());
          throw;
        }
      });
      if (!why.empty() && failures.size() < 10)
        failures.push_back("reader " + std::to_string(r) + " on input " + std::to_string(i) + ": " +
                           why + "\n--- input:\n" + text + "\n---");
      (ok && why.empty() ? accepted : refused) += 1;
    }
  }
  // The manifest of a result set, mutated: problems reported, never an exception.
  const fs::path set = tmp / "set";
  fs::create_directories(set / "refine");
  io::write_file_atomic(set / "a.csv", "x\n1\n");
  int manifests = 0;
  for (int i = 0; i < 500; ++i, ++manifests) {
    std::ofstream(set / io::kManifestName, std::ios::binary | std::ios::trunc)
        << mutate(manifest(), rng);
    const std::string why = outcome([&] { (void)io::check_result_set(set); });
    if (!why.empty() && failures.size() < 10) failures.push_back("manifest " + why);
  }
  std::string all;
  for (const auto& x : failures)
    all += x + "\n";
  INFO(all);
  WARN(inputs << " mutated inputs x " << readers.size() << " readers: " << accepted << " accepted, "
              << refused << " refused; " << manifests << " mutated manifests");
  CHECK(failures.empty());
  CHECK(accepted > 100);  // the mutations leave some inputs readable: the checks ran on data
  CHECK(refused > 1000);
}

#include "errsep/io/raw_scan_csv.hpp"

#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <limits>

#include "support/support.hpp"

using namespace errsep::io;
using errsep::test::TempDir;

namespace {
RawFourSensorScan sample_scan(bool complete) {
  RawFourSensorScan s;
  errsep::core::FourSensorConfig g;
  g.dx_mm = 2.0;
  g.s2 = 1;
  g.s3 = 1;
  g.s4 = 2;
  g.N = 13;  // P = 9
  s.geometry = g;
  for (int n = 0; n < 9; ++n) {
    s.x_mm.push_back(2.0 * n);
    for (std::size_t i = 0; i < 4; ++i)
      s.m_um[i].push_back(n == 1 ? -0.25 : 1.0 + static_cast<double>(i) + 3.125e-3 * n);
  }
  s.t_s.emplace();
  for (std::size_t i = 0; i < 4; ++i)
    for (int n = 0; n < 9; ++n)
      (*s.t_s)[i].push_back(0.1 * n + static_cast<double>(i));
  s.complete = complete;
  s.metadata = {{"samples", "1600"}, {"stop_reason", complete ? "" : "aborted by user"}};
  return s;
}
}  // namespace

TEST_CASE("four-sensor raw scan round-trips, geometry and metadata included") {
  TempDir dir;
  const auto s = sample_scan(true);
  write_raw_four_sensor_csv(dir / "raw.csv", s);
  const auto r = read_raw_four_sensor_csv(dir / "raw.csv");
  CHECK(r.complete);
  CHECK(r.x_mm == s.x_mm);
  for (std::size_t i = 0; i < 4; ++i)
    CHECK(r.m_um[i] == s.m_um[i]);
  REQUIRE(r.t_s);
  CHECK((*r.t_s)[3] == (*s.t_s)[3]);
  REQUIRE(r.geometry);
  CHECK(r.geometry->s4 == 2);
  CHECK(r.geometry->N == 13);
  CHECK(r.meta("samples") == std::optional<std::string>("1600"));
  // The exact header errsep-separate expects.
  std::ifstream in(dir / "raw.csv");
  std::string line, header;
  while (std::getline(in, line))
    if (!line.empty() && line[0] != '#') {
      header = line;
      break;
    }
  CHECK(header == "x_mm,m1_um,m2_um,m3_um,m4_um,t1_s,t2_s,t3_s,t4_s");
}

TEST_CASE("an incomplete scan is refused for separation, readable for inspection") {
  TempDir dir;
  auto s = sample_scan(false);
  s.m_um[3][2] = std::numeric_limits<double>::quiet_NaN();
  s.m_um[3][3] = std::numeric_limits<double>::quiet_NaN();
  write_raw_four_sensor_csv(dir / "raw.csv", s);
  try {
    (void)read_raw_four_sensor_csv(dir / "raw.csv");
    FAIL("incomplete scan accepted");
  } catch (const CsvError& e) {
    CHECK_THAT(e.what(), Catch::Contains("incomplete") && Catch::Contains("aborted by user"));
  }
  RawReadOptions o;
  o.require_complete = false;
  const auto r = read_raw_four_sensor_csv(dir / "raw.csv", o);
  CHECK_FALSE(r.complete);
  CHECK(std::isnan(r.m_um[3][2]));
  CHECK(r.m_um[3][1] == -0.25);
}

TEST_CASE(
    "a plain CSV with the four-sensor columns is accepted, but nan in a complete scan is not") {
  TempDir dir;
  {
    std::ofstream f(dir / "plain.csv");
    f << "x_mm,m1_um,m2_um,m3_um,m4_um\n0,1,2,3,4\n5,1.5,2.5,3.5,4.5\n";
  }
  const auto r = read_raw_four_sensor_csv(dir / "plain.csv");
  CHECK(r.complete);
  CHECK(r.positions() == 2);
  CHECK_FALSE(r.t_s);
  CHECK_FALSE(r.geometry);
  {
    std::ofstream f(dir / "nan.csv");
    f << "x_mm,m1_um,m2_um,m3_um,m4_um\n0,1,2,3,4\n5,1.5,nan,3.5,4.5\n";
  }
  CHECK_THROWS_WITH(read_raw_four_sensor_csv(dir / "nan.csv"),
                    Catch::Contains("nan.csv:3") && Catch::Contains("m2_um"));
  {
    std::ofstream f(dir / "short.csv");
    f << "x_mm,m1_um,m2_um,m4_um\n0,1,2,4\n";
  }
  CHECK_THROWS_WITH(read_raw_four_sensor_csv(dir / "short.csv"),
                    Catch::Contains("missing column 'm3_um'"));
}

TEST_CASE("displacement raw scan round-trips with d") {
  TempDir dir;
  RawDisplacementScan s;
  s.x_mm = {0, 5, 10};
  s.s1_scan1_um = {1, 2, 3};
  s.s2_scan1_um = {4, 5, 6};
  s.s1_scan2_um = {1.1, 2.1, 3.1};
  s.s2_scan2_um = {4.5, 5.5, 6.5};
  s.d_mm = 5.0;
  s.complete = true;
  write_raw_displacement_csv(dir / "d.csv", s);
  const auto r = read_raw_displacement_csv(dir / "d.csv");
  CHECK(r.d_mm == 5.0);
  CHECK(r.s2_scan2_um == s.s2_scan2_um);
  CHECK_THROWS_WITH(read_raw_four_sensor_csv(dir / "d.csv"),
                    Catch::Contains("not a four-sensor raw scan"));
}

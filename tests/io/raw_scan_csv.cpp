#include "errsep/io/raw_scan_csv.hpp"

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <limits>
#include <tuple>

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

namespace {

std::string where(const std::filesystem::path& file, std::size_t n) {
  return file.string() + ":" + std::to_string(errsep::test::data_line(file, n)) + ": ";
}

/// A complete four-point displacement scan with reading times, scan 2 in the paper's order.
RawDisplacementScan four_point_displacement_scan() {
  RawDisplacementScan s;
  s.x_mm = {0, 5, 10, 15};
  s.s1_scan1_um = {1, 2, 3, 4};
  s.s2_scan1_um = {4, 5, 6, 7};
  s.s1_scan2_um = {1.1, 2.1, 3.1, 4.1};
  s.s2_scan2_um = {4.5, 5.5, 6.5, 7.5};
  s.t_scan1_s = std::vector<double>{0, 1, 2, 3};
  s.t_scan2_s = std::vector<double>{4, 5, 6, 7};
  s.d_mm = 5.0;
  s.complete = true;
  return s;
}

}  // namespace

TEST_CASE("impossible readings, positions and times are refused with file:line") {
  TempDir dir;
  const auto file = dir / "raw.csv";
  auto s = sample_scan(true);
  for (int i = 1; i <= 4; ++i) {
    const std::string m = "m" + std::to_string(i);
    s.metadata.emplace_back("range_min_" + m + "_um", "-2000");
    s.metadata.emplace_back("range_max_" + m + "_um", "2000");
  }
  write_raw_four_sensor_csv(file, s);
  REQUIRE_NOTHROW(read_raw_four_sensor_csv(file));
  auto refused = [&](const RawFourSensorScan& bad, std::size_t row, const std::string& what) {
    write_raw_four_sensor_csv(file, bad);
    try {
      (void)read_raw_four_sensor_csv(file);
      FAIL("accepted: " << what);
    } catch (const CsvError& e) {
      CHECK_THAT(e.what(), Catch::StartsWith(where(file, row)) && Catch::Contains(what));
    }
  };
  SECTION("a reading no sensor can give (-8.7e10 um, issue 21)") {
    auto b = s;
    b.m_um[1][5] = -8.7e10;
    refused(b, 5, "column 'm2_um': -8.7e+10 um is outside the sensor's range -2000 to 2000 um");
  }
  SECTION("just outside the recorded range") {
    auto b = s;
    b.m_um[3][0] = 2000.001;
    refused(b, 0, "column 'm4_um': 2000.001 um is outside the sensor's range");
  }
  SECTION("without a recorded range: the bound of any displacement sensor") {
    auto b = sample_scan(true);
    b.m_um[1][5] = -8.7e10;
    refused(b, 5, "beyond any displacement sensor (the file records no range");
  }
  SECTION("inf, in a complete and in an incomplete scan") {
    auto b = s;
    b.m_um[2][3] = std::numeric_limits<double>::infinity();
    refused(b, 3, "column 'm3_um': inf is not a finite reading");
    b.complete = false;
    write_raw_four_sensor_csv(file, b);
    RawReadOptions inspect;
    inspect.require_complete = false;
    CHECK_THROWS_WITH(read_raw_four_sensor_csv(file, inspect),
                      Catch::StartsWith(where(file, 3)) && Catch::Contains("not a finite"));
  }
  SECTION("nan in a scan marked complete") {
    auto b = s;
    b.m_um[0][7] = std::numeric_limits<double>::quiet_NaN();
    refused(b, 7, "not measured, in a scan marked complete");
  }
  SECTION("a position out of order") {
    auto b = s;
    b.x_mm[4] = b.x_mm[2];
    refused(b, 4, "column 'x_mm': 4 after 6");
  }
  SECTION("a time going backwards") {
    auto b = s;
    (*b.t_s)[2][6] = (*b.t_s)[2][5] - 0.01;
    refused(b, 6, "column 't3_s'");
    CHECK_THROWS_WITH(read_raw_four_sensor_csv(file), Catch::Contains("time goes backwards"));
  }
  SECTION("half a range in the metadata") {
    auto b = sample_scan(true);
    b.metadata.emplace_back("range_min_m1_um", "-2000");
    write_raw_four_sensor_csv(file, b);
    CHECK_THROWS_WITH(read_raw_four_sensor_csv(file),
                      Catch::Contains("range_min_m1_um") && Catch::Contains("range_max_m1_um"));
  }
}

TEST_CASE("impossible values of a displacement raw scan are refused with file:line") {
  TempDir dir;
  const auto file = dir / "d.csv";
  RawDisplacementScan s = four_point_displacement_scan();
  s.metadata = {{"range_min_s1_um", "-100"},
                {"range_max_s1_um", "100"},
                {"range_min_s2_um", "-100"},
                {"range_max_s2_um", "100"}};
  write_raw_displacement_csv(file, s);
  REQUIRE_NOTHROW(read_raw_displacement_csv(file));
  auto b = s;
  b.s2_scan2_um[2] = 100.5;
  write_raw_displacement_csv(file, b);
  CHECK_THROWS_WITH(read_raw_displacement_csv(file),
                    Catch::StartsWith(where(file, 2)) &&
                        Catch::Contains("'s2_scan2_um': 100.5 um is outside the sensor's range"));
  b = s;
  (*b.t_scan2_s)[3] = 4.5;
  write_raw_displacement_csv(file, b);
  CHECK_THROWS_WITH(read_raw_displacement_csv(file),
                    Catch::StartsWith(where(file, 3)) && Catch::Contains("time goes backwards"));
  b = s;
  b.x_mm[1] = -1;
  write_raw_displacement_csv(file, b);
  CHECK_THROWS_WITH(
      read_raw_displacement_csv(file),
      Catch::StartsWith(where(file, 1)) && Catch::Contains("positions must increase"));
}

// Issue 16 item 2: a scan sequence's traverses are recorded per reading (traverse, direction,
// time), and today's files read as the single plan.
TEST_CASE("a scan sequence round-trips, and a file without traverses is the single plan") {
  TempDir dir;
  auto s = sample_scan(true);
  const auto seq = errsep::core::ScanSequence::make(errsep::core::ScanSequenceKind::reversed,
                                                    *s.geometry, 4.0, 1.5);
  const Eigen::MatrixXd t = seq.times_s(*s.geometry);
  Eigen::MatrixXd m(9, seq.size());
  for (Eigen::Index k = 0; k < m.cols(); ++k)
    for (Eigen::Index n = 0; n < 9; ++n)
      m(n, k) = 0.5 * static_cast<double>(k) + 1e-3 * static_cast<double>(n * n);
  set_sequence(s, seq, m, t);
  write_raw_four_sensor_csv(dir / "seq.csv", s);
  const auto r = read_raw_four_sensor_csv(dir / "seq.csv");
  REQUIRE(r.sequence);
  CHECK(r.sequence->plan == "reversed");
  REQUIRE(r.sequence->traverses.size() == 8);
  CHECK(r.sequence->traverses[1].configuration == 0);
  CHECK(r.sequence->traverses[1].direction == errsep::core::TraverseDirection::backward);
  CHECK(r.sequence->traverses[3].start_s == Approx(seq.traverses[3].start_s));
  CHECK(r.sequence->m_um[5] == s.sequence->m_um[5]);
  CHECK(r.sequence->t_s[1].front() == Approx(t(0, 1)));  // backward: x_0 read last
  CHECK(r.m_um[1] == s.sequence->m_um[2]);  // m2: the first traverse of configuration 2
  CHECK_FALSE(r.meta("traverse_1"));        // sequence lines are not "other" metadata
  const auto [rseq, rm] = scan_sequence_of(r);
  CHECK(rseq.name == "reversed");
  CHECK(rseq.size() == 8);
  CHECK(rseq.speed_mm_per_s == Approx(4.0));
  CHECK((rm - m).cwiseAbs().maxCoeff() < 1e-9);
  // Today's file: no traverses -> the single plan from m1..m4.
  write_raw_four_sensor_csv(dir / "plain.csv", sample_scan(true));
  const auto plain = read_raw_four_sensor_csv(dir / "plain.csv");
  CHECK_FALSE(plain.sequence);
  const auto [pseq, pm] = scan_sequence_of(plain);
  CHECK(pseq.name == "single");
  CHECK(pm.cols() == 4);
  CHECK(pm(3, 2) == plain.m_um[2][3]);
}

// The serpentine plan reads configurations 2 and 4 backward on their first (only) traverse: m2's
// times t2_s then decrease down the rows, which the reader accepts because the traverse line says
// backward; a backward traverse whose times increase is refused naming the line that said so.
TEST_CASE(
    "a serpentine plan's backward first traverses round-trip, times against the direction "
    "are refused") {
  TempDir dir;
  auto s = sample_scan(true);
  const auto seq =
      errsep::core::ScanSequence::make(errsep::core::ScanSequenceKind::serpentine, *s.geometry);
  CHECK(seq.name == "serpentine");
  const Eigen::MatrixXd t = seq.times_s(*s.geometry);
  set_sequence(s, seq, Eigen::MatrixXd::Zero(9, seq.size()), t);
  write_raw_four_sensor_csv(dir / "serp.csv", s);
  const auto r = read_raw_four_sensor_csv(dir / "serp.csv");
  REQUIRE(r.sequence);
  CHECK(r.sequence->plan == "serpentine");
  REQUIRE(r.sequence->traverses.size() == 5);
  CHECK(r.sequence->traverses[1].direction == errsep::core::TraverseDirection::backward);
  CHECK(r.sequence->traverses[4].direction == errsep::core::TraverseDirection::backward);
  REQUIRE(r.t_s);
  CHECK((*r.t_s)[1].front() > (*r.t_s)[1].back());  // configuration 2: x_0 read last
  CHECK(scan_sequence_of(r).first.name == "serpentine");
  // Traverse 2 declared backward, its times increasing down the rows.
  auto bad = s;
  std::reverse(bad.sequence->t_s[1].begin(), bad.sequence->t_s[1].end());
  write_raw_four_sensor_csv(dir / "bad.csv", bad);
  CHECK_THROWS_WITH(read_raw_four_sensor_csv(dir / "bad.csv"),
                    Catch::Contains("bad.csv") && Catch::Contains("k2_t_s") &&
                        Catch::Contains("traverse_2 is backward") &&
                        Catch::Contains("time goes backwards"));
}

TEST_CASE("a bad traverse line is refused with file and what is wrong") {
  TempDir dir;
  auto s = sample_scan(true);
  const auto seq =
      errsep::core::ScanSequence::make(errsep::core::ScanSequenceKind::closing_pass, *s.geometry);
  set_sequence(s, seq, Eigen::MatrixXd::Zero(9, 5), seq.times_s(*s.geometry));
  auto t = to_csv_table(s);
  t.set_meta("traverse_3", "configuration 7, sideways, start_s 1");
  errsep::io::write_csv(dir / "bad.csv", t);
  try {
    read_raw_four_sensor_csv(dir / "bad.csv");
    FAIL("accepted a bad traverse line");
  } catch (const CsvError& e) {
    const std::string w = e.what();
    CHECK(w.find("bad.csv") != std::string::npos);
    CHECK(w.find("traverse_3") != std::string::npos);
  }
}

// Issue 16 item 2: the rezeroed plan's traverses carry their stated zero shift; the file records
// it on the traverse line (only where it is not 0), reads it back, and refuses a malformed one
// naming the file and the line's key.
TEST_CASE("a rezeroed plan's zero shifts round-trip, and a bad one is refused") {
  TempDir dir;
  auto s = sample_scan(true);
  const auto seq = errsep::core::ScanSequence::make(errsep::core::ScanSequenceKind::rezeroed,
                                                    *s.geometry, 4.0, 1.5, 37.25);
  Eigen::MatrixXd m(9, seq.size());
  for (Eigen::Index k = 0; k < m.cols(); ++k)
    for (Eigen::Index n = 0; n < 9; ++n)
      m(n, k) = (k >= 4 ? 37.25 : 0.0) + 1e-3 * static_cast<double>(n * n + k);
  set_sequence(s, seq, m, seq.times_s(*s.geometry));
  const auto file = dir / "rz.csv";
  write_raw_four_sensor_csv(file, s);
  const std::string text = errsep::test::read_file(file);
  CHECK_THAT(text, Catch::Contains("# plan: rezeroed"));
  CHECK_THAT(text, Catch::Contains("# traverse_5: configuration 1, forward, start_s"));
  CHECK_THAT(text, Catch::Contains(", zero_shift_um 37.25"));
  {
    const auto at = text.find("# traverse_4:");
    REQUIRE(at != std::string::npos);
    CHECK(text.substr(at, text.find('\n', at) - at).find("zero_shift") == std::string::npos);
  }
  const auto r = read_raw_four_sensor_csv(file);
  REQUIRE(r.sequence);
  REQUIRE(r.sequence->traverses.size() == 8);
  for (std::size_t k = 0; k < 8; ++k)
    CHECK(r.sequence->traverses[k].zero_shift_um == (k >= 4 ? 37.25 : 0.0));
  const auto [rseq, rm] = scan_sequence_of(r);
  CHECK(rseq.rezeroed());
  CHECK(rseq.name == "rezeroed");
  CHECK((rm - m).cwiseAbs().maxCoeff() < 1e-9);
  // Malformed: a word for the shift, a trailing field, and a shift on traverse 1 (its zero is
  // the reference).
  for (const auto& [key, line, what] :
       {std::tuple<std::string, std::string, std::string>{
            "traverse_6", "configuration 2, forward, start_s 40, zero_shift_um lots",
            "zero_shift_um"},
        {"traverse_7", "configuration 3, forward, start_s 60, zero_shift_um 3, tilt 1",
         "zero_shift_um"},
        {"traverse_1", "configuration 1, forward, start_s 0, zero_shift_um 5", "traverse 1"}}) {
    auto t = to_csv_table(s);
    t.set_meta(key, line);
    errsep::io::write_csv(dir / "bad.csv", t);
    try {
      read_raw_four_sensor_csv(dir / "bad.csv");
      FAIL("accepted '" + line + "'");
    } catch (const CsvError& e) {
      const std::string w = e.what();
      CHECK(w.rfind((dir / "bad.csv").string(), 0) == 0);
      CHECK(w.find(what) != std::string::npos);
      if (key != "traverse_1") CHECK(w.find(key) != std::string::npos);
    }
  }
}

// Issue 16: every error in a traverse header line says file:line (the line it concerns), and
// what is wrong.  The expected line is found in the written text, not assumed: each bad line
// replaces a good one in place, and a missing traverse names the line that announced T of them.
TEST_CASE("a bad traverse header line is refused as file:line: what is wrong") {
  TempDir dir;
  auto s = sample_scan(true);
  const auto seq = errsep::core::ScanSequence::make(errsep::core::ScanSequenceKind::rezeroed,
                                                    *s.geometry, 4.0, 1.5, 20.0);
  set_sequence(s, seq, Eigen::MatrixXd::Zero(9, seq.size()), seq.times_s(*s.geometry));
  // The 1-based line of "# key:" in text.
  auto line_of = [](const std::string& text, const std::string& key) {
    const auto at = text.find("# " + key + ":");
    REQUIRE(at != std::string::npos);
    return 1 + std::count(text.begin(), text.begin() + static_cast<std::ptrdiff_t>(at), '\n');
  };
  struct Bad {
    std::string key, value, line_key, what;
  };
  const std::vector<Bad> cases = {
      {"traverse_3", "configuration 7, forward, start_s 1", "traverse_3", "configuration 1..4"},
      {"traverse_2", "configuration 2, sideways, start_s 1", "traverse_2", "forward|backward"},
      {"traverse_4", "configuration 4, forward, start_s soon", "traverse_4", "start_s <s>"},
      {"traverse_6", "configuration 2, forward, start_s 40, zero_shift_um lots", "traverse_6",
       "zero_shift_um <um>"},
      {"traverse_7", "configuration 3, forward, start_s 60, zero_shift_um nan", "traverse_7",
       "a finite number"},
      {"traverse_1", "configuration 1, forward, start_s 0, zero_shift_um 5", "traverses",
       "traverse 1"},
      {"traverses", "eight", "traverses", "not an integer"},
      {"traverses", "3", "traverses", "must be 4..64"},
      {"traverses", "9", "traverses", "'traverse_9' missing"}};
  for (const auto& c : cases) {
    auto t = to_csv_table(s);
    t.set_meta(c.key, c.value);
    const auto file = dir / "bad.csv";
    errsep::io::write_csv(file, t);
    const std::string text = errsep::test::read_file(file);
    const auto line = static_cast<std::size_t>(line_of(text, c.line_key));
    INFO(c.key << ": " << c.value);
    try {
      read_raw_four_sensor_csv(file);
      FAIL("accepted '" + c.key + ": " + c.value + "'");
    } catch (const CsvError& e) {
      const std::string w = e.what();
      CHECK(e.line() == line);
      CHECK_THAT(w, Catch::StartsWith(file.string() + ":" + std::to_string(line) + ": "));
      CHECK_THAT(w, Catch::Contains(c.what));
    }
  }
}

// Issue 16 item 4: the order of scan 2 is recorded, round-trips, and its times are checked the
// way it ran; a file without it is the paper's order.
TEST_CASE("a displacement scan's scan-2 order round-trips and its times are checked that way") {
  TempDir dir;
  const auto file = dir / "d.csv";
  RawDisplacementScan s = four_point_displacement_scan();
  s.t_scan2_s = std::vector<double>{7, 6, 5, 4};  // scan 2 from the last point back
  s.scan2_order = errsep::core::DisplacementScanOrder::backward;
  write_raw_displacement_csv(file, s);
  CHECK_THAT(errsep::test::read_file(file), Catch::Contains("# scan2_order: backward"));
  const auto r = read_raw_displacement_csv(file);
  CHECK(r.scan2_order == errsep::core::DisplacementScanOrder::backward);
  CHECK(*r.t_scan2_s == *s.t_scan2_s);
  for (const auto& kv : r.metadata)
    CHECK(kv.first != "scan2_order");  // read into the field, not left in the metadata

  // Times that run forward in a scan recorded backward: refused at the row where they turn.
  auto b = s;
  (*b.t_scan2_s)[1] = 3.5;
  write_raw_displacement_csv(file, b);
  CHECK_THROWS_WITH(read_raw_displacement_csv(file),
                    Catch::StartsWith(where(file, 1)) &&
                        Catch::Contains("scan2_order is backward") &&
                        Catch::Contains("time goes backwards"));
  // The same times recorded as forward: refused as before.
  b = s;
  b.scan2_order = errsep::core::DisplacementScanOrder::forward;
  write_raw_displacement_csv(file, b);
  CHECK_THROWS_WITH(read_raw_displacement_csv(file), Catch::Contains("time goes backwards"));
  // An order nobody knows.
  {
    std::string text = errsep::test::read_file(file);
    const auto at = text.find("# scan2_order: forward");
    REQUIRE(at != std::string::npos);
    text.replace(at, 22, "# scan2_order: sideways");
    std::ofstream(file) << text;
  }
  CHECK_THROWS_WITH(read_raw_displacement_csv(file),
                    Catch::Contains("scan2_order") && Catch::Contains("forward, backward"));
  // A file without the line (written before it existed) is the paper's order.
  b = s;
  b.scan2_order = errsep::core::DisplacementScanOrder::forward;
  b.t_scan2_s = std::vector<double>{4, 5, 6, 7};
  write_raw_displacement_csv(file, b);
  {
    std::string text = errsep::test::read_file(file);
    const auto at = text.find("# scan2_order: forward\n");
    REQUIRE(at != std::string::npos);
    text.erase(at, 23);
    std::ofstream(file) << text;
  }
  CHECK(read_raw_displacement_csv(file).scan2_order ==
        errsep::core::DisplacementScanOrder::forward);
}

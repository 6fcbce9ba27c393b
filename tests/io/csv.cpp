#include "errsep/io/csv.hpp"
#include "errsep/io/atomic_file.hpp"

#include <catch2/catch.hpp>
#include <fstream>

#include "support/support.hpp"

using errsep::io::CsvError;
using errsep::io::CsvTable;

namespace {
void write(const std::filesystem::path& p, const std::string& s) {
  std::ofstream(p) << s;
}
}  // namespace

TEST_CASE("CSV round trip keeps metadata, header and values") {
  errsep::test::TempDir dir;
  CsvTable t;
  t.set_meta("units", "x in mm, values in um");
  t.add_column("x_mm", {0, 5, 10});
  t.add_column("s_um", {0.125, -1.5e-3, 3});
  errsep::io::write_csv(dir / "a.csv", t);
  const auto r = errsep::io::read_csv(dir / "a.csv");
  REQUIRE(r.columns == t.columns);
  REQUIRE(r.meta("units").value() == "x in mm, values in um");
  REQUIRE(r.column("s_um") == std::vector<double>{0.125, -1.5e-3, 3});
  REQUIRE(r.row_line == std::vector<std::size_t>{3, 4, 5});
}

TEST_CASE("CSV errors name the file and the line") {
  errsep::test::TempDir dir;
  const auto p = dir / "bad.csv";
  write(p, "x_mm,m1_um\n0,1\n5\n");
  REQUIRE_THROWS_WITH(errsep::io::read_csv(p),
                      Catch::Contains("bad.csv:3") && Catch::Contains("expected 2 values"));
  write(p, "x_mm,m1_um\n0,1\n5,nan\n");
  REQUIRE_THROWS_WITH(errsep::io::read_csv(p),
                      Catch::Contains("bad.csv:3") && Catch::Contains("non-finite"));
  write(p, "x_mm,m1_um\n0,abc\n");
  REQUIRE_THROWS_WITH(errsep::io::read_csv(p),
                      Catch::Contains("bad.csv:2") && Catch::Contains("not a number"));
  write(p, "# only comments\n");
  REQUIRE_THROWS_WITH(errsep::io::read_csv(p), Catch::Contains("no header"));
  REQUIRE_THROWS_WITH(errsep::io::read_csv(dir / "missing.csv"), Catch::Contains("cannot open"));
  write(p, "x_mm,m1_um\n0,1\n");
  const auto t = errsep::io::read_csv(p);
  REQUIRE_THROWS_WITH(t.column("m2_um", p), Catch::Contains("missing column 'm2_um'"));
}

TEST_CASE("atomic write replaces a file whole and leaves no temporary behind") {
  errsep::test::TempDir dir;
  const auto p = dir / "r.csv";
  write(p, "old");
  errsep::io::write_file_atomic(p, "new content");
  std::ifstream in(p);
  std::string s((std::istreambuf_iterator<char>(in)), {});
  REQUIRE(s == "new content");
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir.path()))
    ++n;
  REQUIRE(n == 1);
  REQUIRE_THROWS_WITH(errsep::io::write_file_atomic(dir / "no-such-dir" / "x.csv", "x"),
                      Catch::Contains("no-such-dir"));
}

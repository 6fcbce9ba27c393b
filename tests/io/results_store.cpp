// The results store: names from UTC time + scan id, atomic writes, scan ids continued from the
// files on disk, a disk-full error that writes nothing, retention only when configured.
#include <catch2/catch.hpp>
#include <chrono>
#include <fstream>
#include <set>

#include "errsep/io/results_store.hpp"
#include "support/support.hpp"

using namespace errsep;
using namespace std::chrono_literals;

namespace {
std::chrono::system_clock::time_point utc(int y, int mo, int d, int h, int mi, int s) {
  std::tm tm{};
  tm.tm_year = y - 1900;
  tm.tm_mon = mo - 1;
  tm.tm_mday = d;
  tm.tm_hour = h;
  tm.tm_min = mi;
  tm.tm_sec = s;
  return std::chrono::system_clock::from_time_t(::timegm(&tm));
}
std::size_t count_files(const std::filesystem::path& dir) {
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir))
    ++n;
  return n;
}
}  // namespace

TEST_CASE("store names: UTC time and scan id, parsed back") {
  const auto t = utc(2026, 11, 23, 8, 43, 7);
  CHECK(io::ResultsStore::stem(t, 42) == "20261123T084307Z_scan000042");
  CHECK(io::ResultsStore::stem(t, 1234567) == "20261123T084307Z_scan1234567");
  const auto f = io::parse_store_name("/x/20261123T084307Z_scan000042.raw-incomplete.csv");
  REQUIRE(f);
  CHECK(f->scan_id == 42);
  CHECK(f->kind == "raw-incomplete");
  CHECK(f->stem == "20261123T084307Z_scan000042");
  CHECK(f->time == t);
  CHECK_FALSE(io::parse_store_name("notes.csv"));
  CHECK_FALSE(io::parse_store_name(".20261123T084307Z_scan000042.raw.csv.tmp.abc123"));
  CHECK_FALSE(io::parse_store_name("20261123T084307Z_scan.raw.csv"));
  CHECK_FALSE(io::parse_store_name("20261123T084307Z_scan000042.csv"));
}

TEST_CASE("writes, next scan id, stale temporaries") {
  test::TempDir tmp;
  io::ResultsStoreOptions o;
  o.dir = tmp / "results";
  o.min_free_bytes = 0;
  io::ResultsStore store(o);
  CHECK(store.next_scan_id() == 1);
  const auto p =
      store.write(io::ResultsStore::stem(utc(2026, 1, 2, 3, 4, 5), 7), "raw", "a,b\n1,2\n");
  CHECK(p == o.dir / "20260102T030405Z_scan000007.raw.csv");
  std::ifstream in(p);
  std::string content((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  CHECK(content == "a,b\n1,2\n");
  CHECK(store.next_scan_id() == 8);
  std::ofstream(o.dir / ".20260102T030405Z_scan000008.raw.csv.tmp.XyZ123") << "partial";
  std::ofstream(o.dir / "operator-notes.txt") << "keep me";
  CHECK(store.list().size() == 1);
  CHECK(store.clean_stale_temporaries() == 1);
  CHECK(std::filesystem::exists(o.dir / "operator-notes.txt"));  // not ours: left alone
  CHECK(count_files(o.dir) == 2);
}

TEST_CASE("checkpoints: removed once superseded by the complete raw file, kept otherwise") {
  test::TempDir tmp;
  io::ResultsStoreOptions o;
  o.dir = tmp / "results";
  o.min_free_bytes = 0;
  io::ResultsStore store(o);
  const auto a = io::ResultsStore::stem(utc(2026, 1, 2, 3, 4, 5), 1);
  const auto b = io::ResultsStore::stem(utc(2026, 1, 2, 3, 5, 0), 2);
  store.write(a, "raw-incomplete", "x\n1\n");  // checkpoint of scan 1...
  store.write(a, "raw", "x\n1\n2\n");          // ...whose complete raw file made it to disk
  store.write(b, "raw-incomplete", "x\n1\n");  // scan 2 was killed: its checkpoint stays
  CHECK(store.remove_superseded() == 1);
  CHECK_FALSE(std::filesystem::exists(store.path(a, "raw-incomplete")));
  CHECK(std::filesystem::exists(store.path(a, "raw")));
  CHECK(std::filesystem::exists(store.path(b, "raw-incomplete")));
  CHECK(store.remove_superseded() == 0);
  CHECK(store.remove(b, "raw-incomplete"));
  CHECK_FALSE(store.remove(b, "raw-incomplete"));  // already gone
  CHECK(count_files(o.dir) == 1);
}

TEST_CASE("disk full: a clear error and nothing written") {
  test::TempDir tmp;
  io::ResultsStoreOptions o;
  o.dir = tmp / "results";
  io::ResultsStore probe(o);
  // A reserve larger than the free space stands in for a full disk.
  o.min_free_bytes = probe.free_bytes() + (1ull << 30);
  io::ResultsStore store(o);
  try {
    store.write("20260102T030405Z_scan000001", "raw", "x_mm\n1\n");
    FAIL("no DiskFullError");
  } catch (const io::DiskFullError& e) {
    const std::string m = e.what();
    CHECK(m.find("disk full") != std::string::npos);
    CHECK(m.find("20260102T030405Z_scan000001.raw.csv") != std::string::npos);
  }
  CHECK(count_files(o.dir) == 0);
}

TEST_CASE("retention: nothing deleted unless configured") {
  test::TempDir tmp;
  io::ResultsStoreOptions o;
  o.dir = tmp / "results";
  o.min_free_bytes = 0;
  const auto now = utc(2026, 11, 23, 12, 0, 0);
  {
    io::ResultsStore store(o);
    for (int id = 1; id <= 5; ++id) {
      const auto stem = io::ResultsStore::stem(now - std::chrono::hours(24 * (6 - id)), id);
      store.write(stem, "raw", "x\n1\n");
      store.write(stem, "result", "x\n1\n");
      // The scan's result folder (service/four_sensor_pipeline.hpp): goes with the scan.
      std::filesystem::create_directories(o.dir / stem);
      std::ofstream(o.dir / stem / "motion.csv") << "x_mm\n1\n";
    }
    CHECK(store.prune(now) == 0);  // retention off by default
    CHECK(store.list().size() == 10);
  }
  SECTION("keep the newest 2 scans") {
    o.retention.keep_scans = 2;
    io::ResultsStore store(o);
    CHECK(store.prune(now) == 6);
    const auto left = store.list();
    REQUIRE(left.size() == 4);
    CHECK(left.front().scan_id == 4);
    CHECK(left.back().scan_id == 5);
    int folders = 0;  // those of scans 4 and 5, the others removed with their scans
    for (const auto& e : std::filesystem::directory_iterator(o.dir))
      folders += e.is_directory() ? 1 : 0;
    CHECK(folders == 2);
    CHECK(std::filesystem::exists(o.dir / left.back().stem / "motion.csv"));
  }
  SECTION("delete scans older than 2.5 days") {
    o.retention.max_age_days = 2.5;
    io::ResultsStore store(o);
    CHECK(store.prune(now) == 6);  // scans 1-3 are 5, 4 and 3 days old
    CHECK(store.list().front().scan_id == 4);
  }
  SECTION("a wrong clock: scans named 1970 after NTP-less boots") {
    // Scans 6 and 7 were made after 5 on a board whose clock restarted at 1970 (no RTC).
    {
      io::ResultsStore store(o);
      const auto epoch = std::chrono::system_clock::time_point{} + std::chrono::hours(1);
      for (int id = 6; id <= 7; ++id) {
        const auto stem = io::ResultsStore::stem(epoch + std::chrono::minutes(id), id);
        store.write(stem, "raw", "x\n1\n");
        store.write(stem, "result", "x\n1\n");
      }
    }
    auto ids = [](const io::ResultsStore& st) {
      std::set<std::uint64_t> v;
      for (const auto& f : st.list())
        v.insert(f.scan_id);
      return v;
    };
    SECTION("count: the newest are the highest ids, not the latest names") {
      o.retention.keep_scans = 3;
      io::ResultsStore store(o);
      CHECK(store.prune(now) == 8);
      CHECK(ids(store) == std::set<std::uint64_t>{5, 6, 7});
    }
    SECTION("age: a 1970 scan after a recent one is at least as recent") {
      o.retention.max_age_days = 2.5;
      io::ResultsStore store(o);
      CHECK(store.prune(now) == 6);  // scans 1-3 only
      CHECK(ids(store) == std::set<std::uint64_t>{4, 5, 6, 7});
    }
    SECTION("age: with the clock itself in 1970 nothing is aged out") {
      o.retention.max_age_days = 2.5;
      io::ResultsStore store(o);
      CHECK(store.prune(std::chrono::system_clock::time_point{} + std::chrono::hours(5)) == 0);
      CHECK(store.list().size() == 14);
    }
  }
  SECTION("age: scans with only implausible times are kept by the age rule") {
    test::TempDir tmp2;
    io::ResultsStoreOptions o2 = o;
    o2.dir = tmp2 / "results";
    o2.retention.max_age_days = 1;
    io::ResultsStore store(o2);
    const auto epoch = std::chrono::system_clock::time_point{};
    store.write(io::ResultsStore::stem(epoch + std::chrono::hours(2), 1), "raw", "x\n1\n");
    // Named after `now` (the clock ran ahead, then was set back): unknown age, kept.
    store.write(io::ResultsStore::stem(now + std::chrono::hours(48), 2), "raw", "x\n1\n");
    CHECK(store.prune(now) == 0);
    CHECK(store.list().size() == 2);
    o2.retention.keep_scans = 1;  // the count rule still applies
    io::ResultsStore counted(o2);
    CHECK(counted.prune(now) == 1);
    REQUIRE(counted.list().size() == 1);
    CHECK(counted.list().front().scan_id == 2);
  }
  SECTION("invalid retention is refused") {
    o.retention.keep_scans = -1;
    CHECK_THROWS_AS(io::ResultsStore(o), std::invalid_argument);
  }
}

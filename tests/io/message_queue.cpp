// The store-and-forward queue on disk: order, exact payloads (binary too), removal, a second
// instance (a restarted process) seeing what the first queued, a temporary of a killed writer
// removed, unparsable files reported and left alone, the scan high-water mark.
#include "errsep/io/message_queue.hpp"

#include <unistd.h>

#include <catch2/catch.hpp>
#include <fstream>

#include "support/support.hpp"

using namespace errsep;

TEST_CASE("message queue: push, pending in order, remove, survives a restart") {
  test::TempDir tmp;
  const auto dir = tmp / "q";
  std::uint64_t a = 0, b = 0, c = 0;
  const std::string binary("x\0y\n\nz", 6);
  {
    io::MessageQueue q(dir);
    CHECK(q.size() == 0);
    a = q.push("errsep/m1/scan/s1", "{\"n\":1}");
    b = q.push("errsep/m1/alarm", binary, true);
    c = q.push("errsep/m1/scan/s2", "");
    CHECK(a < b);
    CHECK(b < c);
    CHECK(q.size() == 3);
  }
  // A temporary left by a writer killed between create and rename.
  std::ofstream(dir / ".00000000000000000001.msg.tmp.abc123") << "half";
  io::MessageQueue q(dir);  // "restart"
  CHECK_FALSE(std::filesystem::exists(dir / ".00000000000000000001.msg.tmp.abc123"));
  auto p = q.pending();
  REQUIRE(p.size() == 3);
  CHECK(p[0].seq == a);
  CHECK(p[0].topic == "errsep/m1/scan/s1");
  CHECK(p[0].payload == "{\"n\":1}");
  CHECK_FALSE(p[0].retain);
  CHECK(p[1].payload == binary);
  CHECK(p[1].retain);
  CHECK(p[2].payload.empty());
  // New pushes sort after the old ones.
  const auto d = q.push("errsep/m1/scan/s3", "3");
  CHECK(d > c);
  CHECK(q.remove(b));
  CHECK_FALSE(q.remove(b));
  p = q.pending();
  REQUIRE(p.size() == 3);
  CHECK(p[1].seq == c);
  CHECK(q.list() == std::vector<std::uint64_t>{a, c, d});
  CHECK_THROWS_AS(q.push("bad\ntopic", "x"), std::invalid_argument);
}

TEST_CASE("message queue: a file that does not parse is reported and left alone") {
  test::TempDir tmp;
  io::MessageQueue q(tmp / "q");
  q.push("t/a", "1");
  std::ofstream(tmp / "q" / "00000000000000000005.msg") << "garbage\n";
  std::vector<std::string> bad;
  const auto p = q.pending(&bad);
  CHECK(p.size() == 1);
  REQUIRE(bad.size() == 1);
  CHECK(bad[0].find("00000000000000000005.msg") != std::string::npos);
  CHECK(std::filesystem::exists(tmp / "q" / "00000000000000000005.msg"));
  std::string why;
  CHECK_FALSE(q.read(5, &why));
  CHECK(why.find("bad header") != std::string::npos);
}

TEST_CASE("message queue: scan high-water mark only rises and persists") {
  test::TempDir tmp;
  {
    io::MessageQueue q(tmp / "q");
    CHECK(q.scan_high_water() == 0);
    q.raise_scan_high_water(7);
    q.raise_scan_high_water(3);
    CHECK(q.scan_high_water() == 7);
  }
  io::MessageQueue q(tmp / "q");
  CHECK(q.scan_high_water() == 7);
  CHECK(q.size() == 0);  // the mark is not a message
}

TEST_CASE("message queue: an unwritable directory is a clear error") {
  if (::geteuid() == 0) {
    // root writes anywhere: use a path under a regular file instead.
    test::TempDir tmp;
    std::ofstream(tmp / "file") << "x";
    CHECK_THROWS_WITH(io::MessageQueue(tmp / "file" / "q"),
                      Catch::Contains("cannot create the directory"));
    return;
  }
  CHECK_THROWS_WITH(io::MessageQueue("/proc/errsep-queue"),
                    Catch::Contains("cannot create the directory"));
}

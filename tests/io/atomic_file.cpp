// write_file_atomic against a real full file system: ENOSPC from write() itself, half-way through
// the file (the daemon's tests hit a full disk earlier, at its free-space check or at the
// temporary file's creation, so this is where the write path's own clean-up is shown).  A tmpfs of
// two pages is mounted in a user+mount namespace of a child process (unshare; skipped with a
// message where namespaces are not available); the child is this same executable running a hidden
// test case in that directory.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <string>
#include <vector>

#include "errsep/io/atomic_file.hpp"
#include "support/support.hpp"

namespace fs = std::filesystem;

namespace {
std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  return {std::istreambuf_iterator<char>(in), {}};
}
std::vector<std::string> entries(const fs::path& dir) {
  std::vector<std::string> v;
  for (const auto& e : fs::directory_iterator(dir))
    v.push_back(e.path().filename().string());
  return v;
}
}  // namespace

// Runs in the child, inside the namespace, with ERRSEP_FULL_DIR on a 8 KiB tmpfs.  Hidden ([.]):
// not registered in ctest on its own.
TEST_CASE("atomic write into a full tmpfs (child)", "[.enospc-child]") {
  const char* env = std::getenv("ERRSEP_FULL_DIR");
  REQUIRE(env != nullptr);
  const fs::path dir = env;
  const fs::path p = dir / "result.csv";
  const std::string small(3000, 'a');
  errsep::io::write_file_atomic(p, small);  // one page of two
  // 20 kB cannot fit: the temporary is created (inodes to spare) and write() fails part-way.
  const std::string big(20000, 'b');
  REQUIRE_THROWS_WITH(errsep::io::write_file_atomic(p, big),
                      Catch::Contains("result.csv': write: disk full (ENOSPC)"));
  // The old file is whole and alone: the temporary was removed, nothing half-written replaced it.
  CHECK(entries(dir) == std::vector<std::string>{"result.csv"});
  CHECK(slurp(p) == small);
  // The space the failed temporary took is free again: a file that fits is still written.
  errsep::io::write_file_atomic(dir / "next.csv", std::string(2000, 'c'));
  CHECK(slurp(dir / "next.csv").size() == 2000);
  std::cout << "child: ENOSPC in write() reported, old file kept whole, no temporary left\n";
}

TEST_CASE("ENOSPC in the middle of a write: clear error, old file kept, no temporary left") {
  errsep::test::TempDir tmp;
  const fs::path dir = tmp / "full";
  fs::create_directories(dir);
  std::string out;
  if (errsep::test::run_command(
          "/usr/bin/unshare -Urm sh -c 'mount -t tmpfs -o size=8k tmpfs " + dir.string() + "' 2>&1",
          &out) != 0) {
    std::cout << "SKIPPED: cannot mount a tmpfs in a user+mount namespace (unshare -Urm): " << out
              << "\n";
    return;
  }
  const fs::path self = fs::read_symlink("/proc/self/exe");
  const std::string cmd = "ERRSEP_FULL_DIR='" + dir.string() +
                          "' /usr/bin/unshare -Urm sh -c 'mount -t tmpfs -o size=8k,nr_inodes=16 "
                          "tmpfs \"$0\" && exec \"$1\" \"[.enospc-child]\"' '" +
                          dir.string() + "' '" + self.string() + "' 2>&1";
  const int rc = errsep::test::run_command(cmd, &out);
  INFO(out);
  CHECK(rc == 0);
  CHECK(out.find("child: ENOSPC in write() reported") != std::string::npos);
  // The tmpfs lived in the child's namespace only: nothing of it is left here.
  CHECK(entries(dir).empty());
}

// The machine config used without --config is this errsep's config/simulator.toml whatever the
// working directory (the README's first job runs errsep-scan from the source tree; a user runs it
// from anywhere).
#include <unistd.h>

#include <catch2/catch.hpp>
#include <filesystem>

#include "errsep/io/default_config.hpp"
#include "support/support.hpp"

using namespace errsep;
namespace fs = std::filesystem;

namespace {

/// Changes the working directory for its lifetime.
struct InDirectory {
  fs::path before = fs::current_path();
  explicit InDirectory(const fs::path& p) { fs::current_path(p); }
  ~InDirectory() { fs::current_path(before); }
};

}  // namespace

TEST_CASE("the default config is found from any working directory") {
  test::TempDir tmp;
  const fs::path expected = fs::canonical(test::source_dir() / "config" / "simulator.toml");
  for (const fs::path& cwd : {tmp.path(), fs::path("/")}) {
    InDirectory in(cwd);
    INFO("working directory " << cwd);
    const fs::path found = io::default_config_file();
    CHECK(fs::canonical(found) == expected);
  }
  // A name that is not there: the error lists where it looked and what to do.
  CHECK_THROWS_WITH(io::default_config_file("no-such-config.toml"),
                    Catch::Contains("searched") && Catch::Contains("--config"));
}

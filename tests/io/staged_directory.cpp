// The result set (io/staged_directory.hpp): one rename makes a set visible whole, an earlier set
// is swapped out whole, a reader refuses a set that is not whole and names what is wrong, and the
// temporaries of dead writers -- and nothing else -- are removed by the next writer.
#include <sys/wait.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <fstream>
#include <set>
#include <sstream>

#include "errsep/io/atomic_file.hpp"
#include "errsep/io/staged_directory.hpp"
#include "support/support.hpp"

using namespace errsep;
namespace fs = std::filesystem;

namespace {

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::set<std::string> names(const fs::path& dir) {
  std::set<std::string> out;
  for (const auto& e : fs::directory_iterator(dir))
    out.insert(e.path().filename().string());
  return out;
}

/// The pid of a process that has ended (and been reaped): a dead writer's.
pid_t dead_pid() {
  const pid_t pid = ::fork();
  if (pid == 0) ::_exit(0);
  ::waitpid(pid, nullptr, 0);
  return pid;
}

std::string joined(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v)
    s += x + "\n";
  return s;
}

/// A committed set of kind `kind` at `out` with the given files (name -> content).
std::string make_set(const fs::path& out, const std::string& kind,
                     const std::vector<std::pair<std::string, std::string>>& files) {
  io::StagedDirectory st(out, {kind, "test", false, {}});
  for (const auto& [name, content] : files) {
    fs::create_directories((st.dir() / name).parent_path());
    io::write_file_atomic(st.dir() / name, content);
  }
  st.commit();
  return st.run_id();
}

}  // namespace

TEST_CASE("a committed set is whole, lists every file, and replaces an earlier set whole") {
  test::TempDir tmp;
  const fs::path out = tmp / "out";
  const std::string id1 =
      make_set(out, "scan", {{"raw.csv", "x_mm\n1\n"}, {"lcurve.csv", "lambda\n1\n"}});
  auto c = io::check_result_set(out);
  INFO(joined(c.problems));
  CHECK(c.whole());
  CHECK(c.kind == "scan");
  CHECK(c.run_id == id1);
  CHECK(c.files == std::vector<std::string>{"lcurve.csv", "raw.csv"});
  CHECK(names(tmp.path()) == std::set<std::string>{"out"});  // no staging folder left

  // The second run has no lcurve.csv: the earlier one must not survive beside the new files.
  const std::string id2 =
      make_set(out, "scan", {{"raw.csv", "x_mm\n2\n"}, {"motion.csv", "x_mm\n2\n"}});
  CHECK(id2 != id1);
  CHECK(names(out) == std::set<std::string>{"raw.csv", "motion.csv", io::kManifestName});
  CHECK(slurp(out / "raw.csv") == "x_mm\n2\n");
  c = io::check_result_set(out);
  CHECK(c.whole());
  CHECK(c.run_id == id2);
  CHECK(names(tmp.path()) == std::set<std::string>{"out"});
  CHECK(io::require_whole_result_set(out));
}

TEST_CASE("a writer replaces only a set of its own kind, an empty or an absent folder") {
  test::TempDir tmp;
  make_set(tmp / "scan", "scan", {{"raw.csv", "x_mm\n1\n"}});
  CHECK_THROWS_WITH(io::StagedDirectory(tmp / "scan", "refine"),
                    Catch::Contains("holds a result set of kind 'scan'") &&
                        Catch::Contains("replace as a whole"));
  fs::create_directories(tmp / "mine");
  std::ofstream(tmp / "mine" / "notes.txt") << "not errsep's";
  CHECK_THROWS_WITH(
      io::StagedDirectory(tmp / "mine", "scan"),
      Catch::Contains("not an errsep result set") && Catch::Contains(io::kManifestName));
  CHECK(slurp(tmp / "mine" / "notes.txt") == "not errsep's");
  std::ofstream(tmp / "file") << "x";
  CHECK_THROWS_WITH(io::StagedDirectory(tmp / "file", "scan"), Catch::Contains("not a folder"));
  fs::create_directories(tmp / "empty");
  make_set(tmp / "empty", "scan", {{"raw.csv", "x_mm\n1\n"}});
  CHECK(io::check_result_set(tmp / "empty").whole());
}

TEST_CASE("the current folder as the target: staged beside it") {
  test::TempDir tmp;
  fs::create_directories(tmp / "here");
  const fs::path cwd = fs::current_path();
  fs::current_path(tmp / "here");
  {
    io::StagedDirectory st(".", "scan");
    CHECK(st.dir().parent_path() == tmp.path());
    io::write_file_atomic(st.dir() / "raw.csv", "x_mm\n1\n");
    st.commit();
  }
  fs::current_path(cwd);
  CHECK(io::check_result_set(tmp / "here").whole());
  CHECK(names(tmp.path()) == std::set<std::string>{"here"});
}

TEST_CASE("an error before commit leaves the target as it was and no staging folder") {
  test::TempDir tmp;
  make_set(tmp / "out", "scan", {{"raw.csv", "x_mm\n1\n"}});
  const auto before = slurp(tmp / "out" / io::kManifestName);
  {
    io::StagedDirectory st(tmp / "out", "scan");
    io::write_file_atomic(st.dir() / "raw.csv", "x_mm\n9\n");
    CHECK(fs::exists(st.dir()));
  }  // no commit: an exception left the scope
  CHECK(slurp(tmp / "out" / io::kManifestName) == before);
  CHECK(slurp(tmp / "out" / "raw.csv") == "x_mm\n1\n");
  CHECK(names(tmp.path()) == std::set<std::string>{"out"});
}

TEST_CASE("a nested set is listed as a set and checked on its own") {
  test::TempDir tmp;
  const fs::path out = tmp / "out";
  io::StagedDirectory st(out, "scan");
  io::write_file_atomic(st.dir() / "raw.csv", "x_mm\n1\n");
  make_set(st.dir() / "refine", "refine", {{"refine_steps.csv", "step\n1\n"}});
  st.commit();
  auto c = io::check_result_set(out);
  INFO(joined(c.problems));
  CHECK(c.whole());
  CHECK(c.files == std::vector<std::string>{"raw.csv", "refine/"});
  // errsep-refine may replace the nested set later: the outer set stays whole.
  make_set(out / "refine", "refine", {{"refine_steps.csv", "step\n2\n"}});
  CHECK(io::check_result_set(out).whole());
  // A nested set that is not whole makes the outer one not whole.
  std::ofstream(out / "refine" / "refine_steps.csv", std::ios::app) << "3\n";
  c = io::check_result_set(out);
  REQUIRE(c.problems.size() == 1);
  CHECK_THAT(c.problems[0], Catch::StartsWith("refine/refine_steps.csv: 9 bytes, the manifest "
                                              "says 7"));
  fs::remove_all(out / "refine");
  c = io::check_result_set(out);
  REQUIRE(c.problems.size() == 1);
  CHECK(c.problems[0] == "missing refine/ (a result set of its own)");
}

TEST_CASE("the reader refuses a set that is not whole and names what is wrong") {
  test::TempDir tmp;
  const fs::path out = tmp / "out";
  make_set(out, "scan",
           {{"raw.csv", "x_mm\n1\n2\n"}, {"motion.csv", "x_mm\n1\n"}, {"plots/s.dat", "1 2\n"}});
  REQUIRE(io::check_result_set(out).whole());

  SECTION("a missing file") {
    fs::remove(out / "motion.csv");
    CHECK_THROWS_WITH(
        io::require_whole_result_set(out),
        Catch::Contains("not a whole result set") && Catch::Contains("missing motion.csv"));
  }
  SECTION("a file cut short") {
    io::write_file_atomic(out / "raw.csv", "x_mm\n1\n");
    CHECK_THROWS_WITH(io::require_whole_result_set(out),
                      Catch::Contains("raw.csv: 7 bytes, the manifest says 9"));
  }
  SECTION("a file of the same size from another run") {
    io::write_file_atomic(out / "raw.csv", "x_mm\n3\n4\n");
    CHECK_THROWS_WITH(io::require_whole_result_set(out), Catch::Contains("raw.csv: CRC-32"));
  }
  SECTION("files added after the run: the set is whole, they are listed apart") {
    std::ofstream(out / "lcurve.csv") << "lambda\n1\n";
    std::ofstream(out / "plots" / "old.png") << "png";
    const auto c = io::check_result_set(out);
    CHECK(c.whole());
    CHECK(c.extra == std::vector<std::string>{"lcurve.csv", "plots/old.png"});
  }
  SECTION("a manifest cut short") {
    const std::string m = slurp(out / io::kManifestName);
    io::write_file_atomic(out / io::kManifestName, m.substr(0, m.size() - 4));
    CHECK_THROWS_WITH(io::require_whole_result_set(out), Catch::Contains("cut short"));
  }
  SECTION("the reader of one file of the set") {
    fs::remove(out / "motion.csv");
    CHECK_THROWS_WITH(io::require_whole_set_of(out / "raw.csv"),
                      Catch::Contains("missing motion.csv"));
  }
  SECTION("temporaries in the folder are not results and are passed over") {
    std::ofstream(out / ".raw.csv.tmp.123.abcdef") << "partial";
    CHECK(io::check_result_set(out).whole());
  }
  // A folder without a manifest cannot be checked: the reader says so by returning false.
  fs::create_directories(tmp / "plain");
  std::ofstream(tmp / "plain" / "motion.csv") << "x\n";
  CHECK_FALSE(io::require_whole_result_set(tmp / "plain"));
}

TEST_CASE("extending a set: its files kept, the writer's own replaced, committed whole anew") {
  test::TempDir tmp;
  const fs::path out = tmp / "out";
  const std::string id = make_set(
      out, "scan", {{"raw.csv", "x_mm\n1\n"}, {"report.html", "old"}, {"plots/old.png", "old"}});
  io::StagedDirectory st(out, {"report", "test-report", true, {"report.html", "plots"}});
  CHECK(fs::exists(st.dir() / "raw.csv"));
  CHECK_FALSE(fs::exists(st.dir() / "report.html"));
  CHECK_FALSE(fs::exists(st.dir() / "plots"));
  io::write_file_atomic(st.dir() / "report.html", "new");
  st.commit();
  const auto c = io::check_result_set(out);
  CHECK(c.whole());
  // The set is still the scan's (a new scan replaces it whole), extended by this run.
  CHECK(c.kind == "scan");
  CHECK(c.run_id == id);
  CHECK(c.writer == "test");
  CHECK(c.run_ids == std::vector<std::string>{id, st.run_id()});
  CHECK(c.files == std::vector<std::string>{"raw.csv", "report.html"});
  CHECK(slurp(out / io::kManifestName).find("extended: " + st.run_id() + " ") != std::string::npos);
  CHECK(slurp(out / "report.html") == "new");
  // A set that is not whole is not extended (its defect would be certified anew).
  fs::remove(out / "raw.csv");
  CHECK_THROWS_WITH(io::StagedDirectory(out, {"report", "test", true, {}}),
                    Catch::Contains("missing raw.csv"));
}

TEST_CASE("temporaries of dead errsep writers are removed, nothing else") {
  test::TempDir tmp;
  const auto dead = std::to_string(dead_pid());
  const auto live = std::to_string(::getpid());
  const std::vector<std::string> stale = {
      ".raw.csv.tmp." + dead + ".Ab12Cd",  // write_file_atomic
      ".out.scan-partial-" + dead,         // a staging folder
      ".out.scan-old-partial-" + dead};    // an earlier set moved aside
  const std::vector<std::string> kept = {".raw.csv.tmp." + live + ".Ab12Cd",  // a live writer's
                                         ".out.refine-partial-" + live,       // ditto
                                         ".raw.csv.tmp.Ab12Cd",  // no pid: not known dead
                                         "raw.csv.tmp." + dead + ".Ab12Cd",  // not hidden: not ours
                                         ".bashrc",
                                         ".cache-partial-x",
                                         ".x.tmp." + dead + ".toolong",
                                         "notes.txt"};
  for (const auto& n : stale) {
    if (n.find("partial") != std::string::npos) {
      fs::create_directories(tmp / n / "sub");
      std::ofstream(tmp / n / "sub" / "motion.csv") << "x";
    } else {
      std::ofstream(tmp / n) << "partial";
    }
  }
  for (const auto& n : kept)
    if (n.find("partial") != std::string::npos)
      fs::create_directories(tmp / n);
    else
      std::ofstream(tmp / n) << "keep";
  CHECK(io::temporary_owner_pid(".raw.csv.tmp." + dead + ".Ab12Cd") == std::stol(dead));
  CHECK(io::temporary_owner_pid(".out.scan-partial-" + dead) == std::stol(dead));
  CHECK(io::temporary_owner_pid(".raw.csv.tmp.Ab12Cd") == 0);
  CHECK(io::temporary_owner_pid("notes.txt") == -1);

  const auto removed = io::remove_stale_temporaries(tmp.path());
  std::set<std::string> got;
  for (const auto& p : removed)
    got.insert(p.filename().string());
  CHECK(got == std::set<std::string>(stale.begin(), stale.end()));
  std::set<std::string> left(kept.begin(), kept.end());
  CHECK(names(tmp.path()) == left);
  const std::string line = io::describe_swept(removed);
  CHECK_THAT(line, Catch::StartsWith("removed 3 temporaries left by an interrupted errsep run: "));
  CHECK(line.find('\n') == std::string::npos);
  CHECK(io::describe_swept({}).empty());
  // The daemon's directory (only the daemon writes there): pid-less ones too.
  CHECK(io::remove_stale_temporaries(tmp.path(), true).size() == 1);
  CHECK_FALSE(fs::exists(tmp / ".raw.csv.tmp.Ab12Cd"));
}

TEST_CASE("writers of single files sweep the folders of their outputs") {
  test::TempDir tmp;
  const auto dead = std::to_string(dead_pid());
  fs::create_directories(tmp / "a");
  std::ofstream(tmp / "a" / (".w.csv.tmp." + dead + ".Ab12Cd")) << "partial";
  std::ofstream(tmp / "a" / "keep.csv") << "x";
  const std::string line =
      io::sweep_beside({tmp / "a" / "w.csv", tmp / "a" / "w.residuals.csv", fs::path()});
  CHECK_THAT(line, Catch::StartsWith("removed 1 temporary left by an interrupted errsep run: "));
  CHECK(names(tmp / "a") == std::set<std::string>{"keep.csv"});
  CHECK(io::sweep_beside({tmp / "a" / "w.csv"}).empty());
}

TEST_CASE("a writer killed before its commit: the next writer removes its staging folder") {
  test::TempDir tmp;
  const fs::path out = tmp / "out";
  make_set(out, "scan", {{"raw.csv", "x_mm\n1\n"}});
  // A child process stages a new set and dies (SIGKILL) before committing it.
  int ready[2];
  REQUIRE(::pipe(ready) == 0);
  const pid_t pid = ::fork();
  if (pid == 0) {
    io::StagedDirectory st(out, "scan");
    io::write_file_atomic(st.dir() / "raw.csv", "x_mm\n2\n");
    char c = 1;
    [[maybe_unused]] const ssize_t n = ::write(ready[1], &c, 1);
    ::pause();
    ::_exit(0);
  }
  char c = 0;
  REQUIRE(::read(ready[0], &c, 1) == 1);
  ::kill(pid, SIGKILL);
  ::waitpid(pid, nullptr, 0);
  ::close(ready[0]);
  ::close(ready[1]);
  const std::string staging = ".out.scan-partial-" + std::to_string(pid);
  REQUIRE(fs::exists(tmp / staging));
  CHECK(io::check_result_set(out).whole());  // the earlier set, whole
  CHECK(slurp(out / "raw.csv") == "x_mm\n1\n");
  io::StagedDirectory next(out, "scan");
  REQUIRE(next.swept().size() == 1);
  CHECK(next.swept()[0].filename() == staging);
  CHECK_FALSE(fs::exists(tmp / staging));
}

TEST_CASE("file_size_and_crc32: the CRC-32 of zlib") {
  test::TempDir tmp;
  io::write_file_atomic(tmp / "a", "123456789");
  const auto [n, crc] = io::file_size_and_crc32(tmp / "a");
  CHECK(n == 9);
  CHECK(crc == 0xCBF43926u);  // the standard check value of CRC-32/ISO-HDLC
}

#include "support/result_files.hpp"

#include "errsep/io/staged_directory.hpp"

namespace errsep::test {

int check_same_result_files(const std::filesystem::path& a, const std::filesystem::path& b) {
  const auto a_files = files_under(a), b_files = files_under(b);
  CHECK(a_files == b_files);
  CHECK(io::check_result_set(a).whole());
  CHECK(io::check_result_set(b).whole());
  int csvs = 0;
  for (const auto& f : b_files)
    if (f.size() > 4 && f.substr(f.size() - 4) == ".csv" && a_files.count(f)) {
      INFO(f);
      CHECK(header_of(a / f) == header_of(b / f));
      CHECK_FALSE(header_of(b / f).empty());
      ++csvs;
    }
  return csvs;
}

void check_report_reads(const std::filesystem::path& dir) {
  std::string out;
  const int rc =
      run_command(app_path("report").string() + " " + dir.string() + " --no-plots", &out);
  INFO(dir.string() << "\n" << out);
  CHECK(rc == 0);
}

}  // namespace errsep::test

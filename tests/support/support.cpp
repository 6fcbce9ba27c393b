#include "support/support.hpp"

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace errsep::test {

TempDir::TempDir() {
  std::string tmpl = (std::filesystem::temp_directory_path() / "errsep-test-XXXXXX").string();
  if (::mkdtemp(tmpl.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
  path_ = tmpl;
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

std::size_t data_line(const std::filesystem::path& csv, std::size_t row) {
  std::ifstream in(csv);
  std::string line;
  std::size_t k = 0;
  while (std::getline(in, line)) {
    ++k;
    if (!line.empty() && line[0] != '#') return k + 1 + row;  // the header, then the rows
  }
  return 0;
}

int run_command(const std::string& cmd, std::string* output) {
  const std::string full = cmd + " 2>&1";
  FILE* p = ::popen(full.c_str(), "r");
  if (!p) return -1;
  std::array<char, 4096> buf{};
  std::string out;
  while (std::fgets(buf.data(), static_cast<int>(buf.size()), p))
    out += buf.data();
  const int status = ::pclose(p);
  if (output) *output = std::move(out);
  if (status == -1 || !WIFEXITED(status)) return -1;
  return WEXITSTATUS(status);
}

std::string read_file(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void replace_once(std::string& s, const std::string& from, const std::string& to) {
  const auto pos = s.find(from);
  if (pos == std::string::npos) throw std::runtime_error("replace_once: '" + from + "' not found");
  s.replace(pos, from.size(), to);
}

}  // namespace errsep::test

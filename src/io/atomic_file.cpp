#include "errsep/io/atomic_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <string>

namespace errsep::io {
namespace {

std::string describe(int err) {
  if (err == ENOSPC) return "disk full (ENOSPC)";
  if (err == EDQUOT) return "disk quota exceeded (EDQUOT)";
  return std::strerror(err);
}

[[noreturn]] void fail(const std::filesystem::path& path, const char* what, int err) {
  throw std::runtime_error("cannot write '" + path.string() + "': " + what + ": " + describe(err));
}

}  // namespace

void write_file_atomic(const std::filesystem::path& path, std::string_view content) {
  const auto dir = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
  // ".<name>.tmp.<pid>.XXXXXX": the pid tells a later run whether the writer is gone, so that
  // what a killed writer left can be removed without touching a live writer's file
  // (remove_stale_temporaries, io/staged_directory.hpp).
  std::string tmpl =
      (dir / ("." + path.filename().string() + ".tmp." + std::to_string(::getpid()) + ".XXXXXX"))
          .string();
  int fd = ::mkstemp(tmpl.data());
  if (fd < 0) fail(path, "create temporary file", errno);
  const std::filesystem::path tmp = tmpl;
  auto cleanup = [&](const char* what, int err) {
    ::close(fd);
    ::unlink(tmp.c_str());
    fail(path, what, err);
  };
  // mkstemp creates 0600; results are meant to be read by the cell controller too.
  if (::fchmod(fd, 0644) != 0) cleanup("chmod", errno);
  const char* p = content.data();
  std::size_t left = content.size();
  while (left > 0) {
    const ssize_t n = ::write(fd, p, left);
    if (n < 0) {
      if (errno == EINTR) continue;
      cleanup("write", errno);
    }
    p += n;
    left -= static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0) cleanup("fsync", errno);
  if (::close(fd) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    fail(path, "close", err);
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    fail(path, "rename", err);
  }
  // The rename is durable only once the directory entry is on disk.
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
}

}  // namespace errsep::io

#include "errsep/acq/sd_notify.hpp"

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

namespace errsep::acq {

SdNotifier::SdNotifier() {
  const char* path = std::getenv("NOTIFY_SOCKET");
  if (const char* usec = std::getenv("WATCHDOG_USEC")) {
    char* end = nullptr;
    const unsigned long long v = std::strtoull(usec, &end, 10);
    bool for_us = true;
    // WATCHDOG_PID, when present, must name this process (a child must not ping for us).
    if (const char* pid = std::getenv("WATCHDOG_PID"))
      for_us = std::strtoll(pid, nullptr, 10) == static_cast<long long>(::getpid());
    if (end && *end == '\0' && v > 0 && for_us) watchdog_ = std::chrono::microseconds(v);
  }
  if (path && *path) open(path);
}

SdNotifier::SdNotifier(std::string socket_path, std::chrono::microseconds watchdog)
    : watchdog_(watchdog) {
  if (!socket_path.empty()) open(socket_path);
}

SdNotifier::~SdNotifier() {
  if (fd_ >= 0) ::close(fd_);
}

void SdNotifier::open(const std::string& path) {
  sockaddr_un sa{};
  sa.sun_family = AF_UNIX;
  if (path.size() >= sizeof sa.sun_path || (path[0] != '/' && path[0] != '@')) {
    error_ = "NOTIFY_SOCKET '" + path + "' is neither an absolute path nor an abstract name (@...)";
    return;
  }
  std::memcpy(sa.sun_path, path.data(), path.size());
  if (path[0] == '@') sa.sun_path[0] = '\0';  // abstract namespace: no terminating NUL counted
  const socklen_t len =
      static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + path.size() + (path[0] == '/'));
  fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0) {
    error_ = std::string("cannot create the notify socket: ") + std::strerror(errno);
    return;
  }
  addr_.assign(reinterpret_cast<const char*>(&sa), len);
}

bool SdNotifier::notify(std::string_view state) const noexcept {
  if (fd_ < 0) return false;
  ssize_t n;
  do {
    n = ::sendto(fd_, state.data(), state.size(), MSG_NOSIGNAL | MSG_DONTWAIT,
                 reinterpret_cast<const sockaddr*>(addr_.data()),
                 static_cast<socklen_t>(addr_.size()));
  } while (n < 0 && errno == EINTR);
  return n == static_cast<ssize_t>(state.size());
}

bool SdNotifier::status(std::string_view text) const {
  std::string msg = "STATUS=";
  msg.append(text);
  for (std::size_t i = 7; i < msg.size(); ++i)
    if (msg[i] == '\n') msg[i] = ' ';
  return notify(msg);
}

}  // namespace errsep::acq

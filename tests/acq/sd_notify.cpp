// sd_notify written by hand: datagrams to a path socket and to an abstract one ('@'), STATUS=
// on one line, watchdog interval from the environment, a no-op without NOTIFY_SOCKET.
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstdlib>
#include <cstring>
#include <string>

#include "errsep/acq/sd_notify.hpp"
#include "support/support.hpp"

using namespace errsep;

namespace {
// Binds a datagram socket; `name` starting with '@' is abstract.
int bind_dgram(const std::string& name) {
  const int fd = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_un sa{};
  sa.sun_family = AF_UNIX;
  std::memcpy(sa.sun_path, name.data(), name.size());
  socklen_t len = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + name.size());
  if (name[0] == '@')
    sa.sun_path[0] = '\0';
  else
    ++len;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&sa), len) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}
std::string recv_one(int fd) {
  timeval tv{2, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  char b[512];
  const ssize_t n = ::recv(fd, b, sizeof b, 0);
  return n > 0 ? std::string(b, static_cast<std::size_t>(n)) : std::string();
}
}  // namespace

TEST_CASE("notify to a path socket") {
  test::TempDir tmp;
  const std::string path = (tmp / "notify").string();
  const int fd = bind_dgram(path);
  REQUIRE(fd >= 0);
  acq::SdNotifier n(path, std::chrono::microseconds(0));
  REQUIRE(n.enabled());
  CHECK(n.ready());
  CHECK(recv_one(fd) == "READY=1");
  CHECK(n.status("scanning\nscan 3"));
  CHECK(recv_one(fd) == "STATUS=scanning scan 3");
  CHECK(n.watchdog());
  CHECK(recv_one(fd) == "WATCHDOG=1");
  ::close(fd);
}

TEST_CASE("notify to an abstract socket, watchdog from the environment") {
  const std::string name = "@errsep-test-notify-" + std::to_string(::getpid());
  const int fd = bind_dgram(name);
  REQUIRE(fd >= 0);
  ::setenv("NOTIFY_SOCKET", name.c_str(), 1);
  ::setenv("WATCHDOG_USEC", "4000000", 1);
  ::setenv("WATCHDOG_PID", std::to_string(::getpid()).c_str(), 1);
  {
    acq::SdNotifier n;
    REQUIRE(n.enabled());
    CHECK(n.watchdog_interval() == std::chrono::seconds(4));
    CHECK(n.stopping());
    CHECK(recv_one(fd) == "STOPPING=1");
  }
  ::setenv("WATCHDOG_PID", "1", 1);  // the watchdog is meant for another process
  {
    acq::SdNotifier n;
    CHECK(n.watchdog_interval().count() == 0);
  }
  ::unsetenv("NOTIFY_SOCKET");
  ::unsetenv("WATCHDOG_USEC");
  ::unsetenv("WATCHDOG_PID");
  {
    acq::SdNotifier n;
    CHECK_FALSE(n.enabled());
    CHECK_FALSE(n.ready());
    CHECK(n.error().empty());
  }
  ::close(fd);
}

TEST_CASE("a NOTIFY_SOCKET that is not a socket address disables the notifier with a reason") {
  acq::SdNotifier n("relative/path", std::chrono::microseconds(0));
  CHECK_FALSE(n.enabled());
  CHECK(n.error().find("relative/path") != std::string::npos);
}

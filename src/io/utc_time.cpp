#include "errsep/io/utc_time.hpp"

#include <ctime>

namespace errsep::io {

std::string utc_iso(std::chrono::system_clock::time_point t) {
  const std::time_t tt = std::chrono::system_clock::to_time_t(t);
  std::tm tm{};
  ::gmtime_r(&tt, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

std::string utc_now_iso() {
  return utc_iso(std::chrono::system_clock::now());
}

}  // namespace errsep::io

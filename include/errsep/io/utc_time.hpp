#pragma once
// UTC times as errsep writes them in file metadata and messages: ISO 8601, seconds, "Z".
#include <chrono>
#include <string>

namespace errsep::io {

/// "YYYY-mm-ddTHH:MM:SSZ" of `t`.
std::string utc_iso(std::chrono::system_clock::time_point t);
/// utc_iso of now.
std::string utc_now_iso();

}  // namespace errsep::io

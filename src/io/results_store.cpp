#include "errsep/io/results_store.hpp"

#include <fcntl.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <map>
#include <set>

#include "errsep/io/atomic_file.hpp"
#include "errsep/io/staged_directory.hpp"

namespace errsep::io {
namespace fs = std::filesystem;

bool RetentionOptions::is_valid(std::string* why) const {
  auto bad = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (keep_scans < 0)
    return bad("retention.keep_scans = " + std::to_string(keep_scans) + ": must be >= 0");
  if (!(max_age_days >= 0))
    return bad("retention.max_age_days = " + std::to_string(max_age_days) + ": must be >= 0");
  return true;
}

bool ResultsStoreOptions::is_valid(std::string* why) const {
  if (dir.empty()) {
    if (why) *why = "results dir: must not be empty";
    return false;
  }
  return retention.is_valid(why);
}

ResultsStore::ResultsStore(ResultsStoreOptions opts) : opts_(std::move(opts)) {
  std::string why;
  if (!opts_.is_valid(&why)) throw std::invalid_argument("results store: " + why);
  std::error_code ec;
  fs::create_directories(opts_.dir, ec);
  if (ec)
    throw std::runtime_error("results directory '" + opts_.dir.string() +
                             "' cannot be created: " + ec.message());
  if (::access(opts_.dir.c_str(), W_OK | X_OK) != 0)
    throw std::runtime_error("results directory '" + opts_.dir.string() +
                             "' is not writable: " + std::strerror(errno));
}

std::string ResultsStore::stem(std::chrono::system_clock::time_point t, std::uint64_t scan_id) {
  const std::time_t tt = std::chrono::system_clock::to_time_t(t);
  std::tm tm{};
  ::gmtime_r(&tt, &tm);
  char buf[64];
  std::strftime(buf, sizeof buf, "%Y%m%dT%H%M%SZ", &tm);
  char id[32];
  std::snprintf(id, sizeof id, "%06llu", static_cast<unsigned long long>(scan_id));
  return std::string(buf) + "_scan" + id;
}

fs::path ResultsStore::path(std::string_view stem_, std::string_view kind) const {
  return opts_.dir / (std::string(stem_) + "." + std::string(kind) + ".csv");
}

std::uint64_t ResultsStore::free_bytes() const {
  struct statvfs st {};
  if (::statvfs(opts_.dir.c_str(), &st) != 0) return 0;
  return static_cast<std::uint64_t>(st.f_bavail) * st.f_frsize;
}

fs::path ResultsStore::write(std::string_view stem_, std::string_view kind,
                             std::string_view content) {
  const fs::path p = path(stem_, kind);
  const std::uint64_t free = free_bytes();
  if (free < opts_.min_free_bytes + content.size())
    throw DiskFullError("cannot write '" + p.string() + "': disk full: " + std::to_string(free) +
                        " bytes free, " + std::to_string(content.size()) +
                        " needed plus a reserve of " + std::to_string(opts_.min_free_bytes) +
                        " (free space in the results directory, or enable retention)");
  try {
    write_file_atomic(p, content);
  } catch (const std::runtime_error& e) {
    // write_file_atomic names ENOSPC/EDQUOT in its message; keep that as its own error type so
    // the daemon reports "disk full" and not a generic write failure.
    const std::string m = e.what();
    if (m.find("(ENOSPC)") != std::string::npos || m.find("(EDQUOT)") != std::string::npos)
      throw DiskFullError(m);
    throw;
  }
  return p;
}

bool ResultsStore::remove(std::string_view stem_, std::string_view kind) {
  const fs::path p = path(stem_, kind);
  if (::unlink(p.c_str()) != 0) {
    if (errno == ENOENT) return false;
    throw std::runtime_error("cannot remove '" + p.string() + "': " + std::strerror(errno));
  }
  // The removal is durable only once the directory is on disk (as for the rename of a write).
  const int dfd = ::open(opts_.dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
  return true;
}

std::optional<StoredFile> parse_store_name(const fs::path& file) {
  const std::string name = file.filename().string();
  // <8 digits>T<6 digits>Z_scan<digits>.<kind>.csv
  if (name.size() < 16 + 5 + 1 + 1 + 4 || name[0] == '.') return std::nullopt;
  if (name.compare(name.size() - 4, 4, ".csv") != 0) return std::nullopt;
  std::tm tm{};
  int consumed = 0;
  if (std::sscanf(name.c_str(), "%4d%2d%2dT%2d%2d%2dZ_scan%n", &tm.tm_year, &tm.tm_mon, &tm.tm_mday,
                  &tm.tm_hour, &tm.tm_min, &tm.tm_sec, &consumed) != 6 ||
      consumed != 21)
    return std::nullopt;
  std::size_t i = static_cast<std::size_t>(consumed), j = i;
  while (j < name.size() && name[j] >= '0' && name[j] <= '9')
    ++j;
  if (j == i || j >= name.size() || name[j] != '.') return std::nullopt;
  const std::size_t kind_end = name.size() - 4;
  if (kind_end <= j + 1) return std::nullopt;
  StoredFile f;
  f.path = file;
  f.stem = name.substr(0, j);
  f.scan_id = std::stoull(name.substr(i, j - i));
  f.kind = name.substr(j + 1, kind_end - j - 1);
  tm.tm_year -= 1900;
  tm.tm_mon -= 1;
  f.time = std::chrono::system_clock::from_time_t(::timegm(&tm));
  return f;
}

std::vector<StoredFile> ResultsStore::list() const {
  std::vector<StoredFile> out;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(opts_.dir, ec)) {
    if (!e.is_regular_file(ec)) continue;
    if (auto f = parse_store_name(e.path())) out.push_back(std::move(*f));
  }
  std::sort(out.begin(), out.end(),
            [](const StoredFile& a, const StoredFile& b) { return a.path < b.path; });
  return out;
}

std::uint64_t ResultsStore::next_scan_id() const {
  std::uint64_t hi = 0;
  for (const auto& f : list())
    hi = std::max(hi, f.scan_id);
  return hi + 1;
}

int ResultsStore::clean_stale_temporaries() {
  // write_file_atomic's temporaries (".<name>.tmp.<pid>.XXXXXX") of processes that are gone, and
  // those of older versions without a pid: the daemon is the only writer of its directory.
  return static_cast<int>(remove_stale_temporaries(opts_.dir, true).size());
}

int ResultsStore::remove_superseded() {
  std::set<std::string> complete;
  const std::vector<StoredFile> files = list();
  for (const auto& f : files)
    if (f.kind == "raw") complete.insert(f.stem);
  int n = 0;
  for (const auto& f : files)
    if (f.kind == "raw-incomplete" && complete.count(f.stem) && remove(f.stem, f.kind)) ++n;
  return n;
}

std::chrono::system_clock::time_point earliest_plausible_scan_time() {
  return std::chrono::sys_days{std::chrono::year{2024} / 1 / 1};
}

int ResultsStore::prune(std::chrono::system_clock::time_point now) {
  if (!opts_.retention.enabled()) return 0;
  // Group files by scan id.  Scans are ranked by id, not by the time in their names: ids only
  // grow (next_scan_id), while a board without a battery-backed clock names its scans 1970 until
  // NTP has synchronised, and ranking by name would then delete the newest scans first.
  std::map<std::uint64_t, std::vector<StoredFile>> scans;
  for (auto& f : list())
    scans[f.scan_id].push_back(f);
  // Age: a scan is at least as recent as every scan before it, so its time is taken as the
  // largest name time up to its id (a scan named 1970 after one named 2026 is at least 2026).
  // Before earliest_plausible_scan_time no scan of this software was made: a time before it (or
  // after `now`, the clock of the scan or of this call being wrong) is unknown and the scan is
  // kept by the age rule; the count rule still applies.
  const auto max_age = std::chrono::duration_cast<std::chrono::system_clock::duration>(
      std::chrono::duration<double, std::ratio<86400>>(opts_.retention.max_age_days));
  const bool now_plausible = now >= earliest_plausible_scan_time();
  std::map<std::uint64_t, std::chrono::system_clock::time_point> lower_bound_time;
  auto running = std::chrono::system_clock::time_point::min();
  for (const auto& [id, files] : scans) {
    for (const auto& f : files)
      running = std::max(running, f.time);
    lower_bound_time[id] = running;
  }
  int removed = 0, rank = 0;
  for (auto it = scans.rbegin(); it != scans.rend(); ++it) {  // newest id first
    ++rank;
    const auto t = lower_bound_time[it->first];
    const bool too_many = opts_.retention.keep_scans > 0 && rank > opts_.retention.keep_scans;
    const bool time_known = now_plausible && t >= earliest_plausible_scan_time() && t <= now;
    const bool too_old = opts_.retention.max_age_days > 0 && time_known && t < now - max_age;
    if (!too_many && !too_old) continue;
    // The raw file last: a stop in between leaves a raw file whose result is made again at the
    // next start (and pruned again), never a result without the raw file it came from.
    std::vector<StoredFile> files = it->second;
    std::stable_partition(files.begin(), files.end(),
                          [](const StoredFile& f) { return f.kind != "raw"; });
    // The scan's result folder (<stem>/, service/four_sensor_pipeline.hpp) goes first too.
    std::error_code dir_ec;
    if (!files.empty() && fs::is_directory(opts_.dir / files.front().stem, dir_ec))
      fs::remove_all(opts_.dir / files.front().stem, dir_ec);
    for (const auto& f : files) {
      std::error_code ec;
      if (fs::remove(f.path, ec)) ++removed;
    }
  }
  return removed;
}

}  // namespace errsep::io

#include "errsep/io/message_queue.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <system_error>

#include "errsep/io/atomic_file.hpp"

namespace errsep::io {
namespace {

constexpr const char* kHeader = "errsep-message 1";
constexpr const char* kHighWater = "scan-high-water";

std::mutex& high_water_mutex() {
  static std::mutex m;
  return m;
}

/// Parses "<20 digits>.msg"; 0 when the name is not a message's.
std::uint64_t seq_of(const std::filesystem::path& p) {
  const std::string n = p.filename().string();
  if (n.size() != 24 || n.compare(20, 4, ".msg") != 0) return 0;
  std::uint64_t v = 0;
  for (std::size_t i = 0; i < 20; ++i) {
    if (n[i] < '0' || n[i] > '9') return 0;
    v = v * 10 + static_cast<std::uint64_t>(n[i] - '0');
  }
  return v;
}

void fsync_dir(const std::filesystem::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd >= 0) {
    ::fsync(fd);
    ::close(fd);
  }
}

}  // namespace

MessageQueue::MessageQueue(std::filesystem::path dir) : dir_(std::move(dir)) {
  std::error_code ec;
  std::filesystem::create_directories(dir_, ec);
  if (ec || !std::filesystem::is_directory(dir_))
    throw std::runtime_error("message queue '" + dir_.string() +
                             "': cannot create the directory: " + ec.message());
  if (::access(dir_.c_str(), W_OK) != 0)
    throw std::runtime_error("message queue '" + dir_.string() + "': directory not writable");
  for (const auto& e : std::filesystem::directory_iterator(dir_, ec)) {
    const std::string n = e.path().filename().string();
    if (n.size() > 5 && n[0] == '.' && n.find(".tmp.") != std::string::npos)
      std::filesystem::remove(e.path(), ec);  // a writer killed between create and rename
  }
  std::uint64_t last = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir_, ec))
    last = std::max(last, seq_of(e.path()));
  last_seq_.store(last);
}

std::filesystem::path MessageQueue::path_of(std::uint64_t seq) const {
  char name[32];
  std::snprintf(name, sizeof name, "%020llu.msg", static_cast<unsigned long long>(seq));
  return dir_ / name;
}

std::uint64_t MessageQueue::push(const std::string& topic, const std::string& payload,
                                 bool retain) {
  if (topic.empty() || topic.find('\n') != std::string::npos)
    throw std::invalid_argument("message queue: topic '" + topic + "' is empty or has a newline");
  // Wall-clock ns keep the order across processes sharing the directory; the counter keeps it
  // within one process when the clock steps back.
  const auto now =
      static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                     std::chrono::system_clock::now().time_since_epoch())
                                     .count());
  std::uint64_t prev = last_seq_.load();
  std::uint64_t seq;
  do {
    seq = std::max(prev + 1, now);
  } while (!last_seq_.compare_exchange_weak(prev, seq));
  std::string content = std::string(kHeader) + "\ntopic: " + topic +
                        "\nretain: " + (retain ? "1" : "0") + "\n\n" + payload;
  write_file_atomic(path_of(seq), content);
  return seq;
}

std::vector<std::uint64_t> MessageQueue::list() const {
  std::vector<std::uint64_t> out;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir_, ec))
    if (const std::uint64_t seq = seq_of(e.path()); seq != 0) out.push_back(seq);
  std::sort(out.begin(), out.end());
  return out;
}

std::optional<QueuedMessage> MessageQueue::read(std::uint64_t seq, std::string* why) const {
  QueuedMessage m;
  m.seq = seq;
  m.file = path_of(seq);
  std::ifstream in(m.file, std::ios::binary);
  if (!in) {
    if (why) *why = m.file.string() + ": gone";
    return std::nullopt;
  }
  std::ostringstream ss;
  ss << in.rdbuf();
  const std::string s = ss.str();
  // header line, topic line, retain line, empty line, payload
  const std::size_t p0 = s.find('\n');
  const std::size_t p1 = p0 == std::string::npos ? p0 : s.find('\n', p0 + 1);
  const std::size_t p2 = p1 == std::string::npos ? p1 : s.find('\n', p1 + 1);
  const bool ok = p2 != std::string::npos && p2 + 1 < s.size() && s[p2 + 1] == '\n' &&
                  s.compare(0, p0, kHeader) == 0 && s.compare(p0 + 1, 7, "topic: ") == 0 &&
                  s.compare(p1 + 1, 8, "retain: ") == 0;
  if (!ok) {
    if (why) *why = m.file.string() + ": not a queued message (bad header)";
    return std::nullopt;
  }
  m.topic = s.substr(p0 + 8, p1 - (p0 + 8));
  const std::string r = s.substr(p1 + 9, p2 - (p1 + 9));
  if (m.topic.empty() || (r != "0" && r != "1")) {
    if (why) *why = m.file.string() + ": not a queued message (topic or retain)";
    return std::nullopt;
  }
  m.retain = r == "1";
  m.payload = s.substr(p2 + 2);
  return m;
}

std::vector<QueuedMessage> MessageQueue::pending(std::vector<std::string>* bad) const {
  std::vector<QueuedMessage> out;
  for (const std::uint64_t seq : list()) {
    std::string why;
    if (auto m = read(seq, &why))
      out.push_back(std::move(*m));
    else if (bad && why.find(": gone") == std::string::npos)
      bad->push_back(why);
  }
  return out;
}

std::size_t MessageQueue::size() const {
  std::size_t n = 0;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir_, ec))
    n += seq_of(e.path()) != 0 ? 1 : 0;
  return n;
}

bool MessageQueue::remove(std::uint64_t seq) {
  std::error_code ec;
  const bool removed = std::filesystem::remove(path_of(seq), ec);
  if (ec)
    throw std::runtime_error("message queue: cannot remove " + path_of(seq).string() + ": " +
                             ec.message());
  if (removed) fsync_dir(dir_);
  return removed;
}

std::uint64_t MessageQueue::scan_high_water() const {
  std::lock_guard<std::mutex> lock(high_water_mutex());
  std::ifstream in(dir_ / kHighWater);
  unsigned long long v = 0;
  if (in >> v) return v;
  return 0;
}

void MessageQueue::raise_scan_high_water(std::uint64_t id) {
  std::lock_guard<std::mutex> lock(high_water_mutex());
  std::ifstream in(dir_ / kHighWater);
  unsigned long long v = 0;
  in >> v;
  if (id <= v) return;
  write_file_atomic(dir_ / kHighWater, std::to_string(id) + "\n");
}

}  // namespace errsep::io

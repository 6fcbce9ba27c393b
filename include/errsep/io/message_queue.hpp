#pragma once
// The store-and-forward queue of outgoing messages (MQTT publishing, service/plant_publisher.hpp):
// one file per message in a directory, written atomically (io/atomic_file.hpp), removed only once
// the broker acknowledged it.  A message is therefore on disk from the moment push() returns
// until its acknowledgement: a broker that is down, a network that drops mid-publish, a SIGKILL
// or a power cut of errsep delays it but never loses it (it may be sent twice: every payload
// carries its scan id so a subscriber can drop the duplicate).
//
// File name "<seq, 20 digits>.msg": the names sort in the order of push(), also across
// processes (seq = max(last seq + 1, wall clock in ns)).  File format, line by line:
//   errsep-message 1
//   topic: <topic>
//   retain: 0|1
//   <empty line>
//   <payload bytes to the end>
// A file that does not parse (written by something else) is reported by pending() and left alone.
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace errsep::io {

struct QueuedMessage {
  std::uint64_t seq = 0;
  std::filesystem::path file;
  std::string topic;
  std::string payload;
  bool retain = false;
};

class MessageQueue {
 public:
  /// Creates the directory if needed and removes temporaries of a killed writer.  Throws
  /// std::runtime_error naming the directory when it cannot be created or written.
  explicit MessageQueue(std::filesystem::path dir);

  const std::filesystem::path& dir() const noexcept { return dir_; }

  /// Writes the message durably and returns its sequence number.  Throws std::runtime_error
  /// (disk full, ...) when it could not be written: then nothing was queued.  Thread-safe.
  std::uint64_t push(const std::string& topic, const std::string& payload, bool retain = false);

  /// Sequence numbers of the queued messages, oldest first (names only; nothing read).
  std::vector<std::uint64_t> list() const;
  /// Reads one message; nullopt when it is gone (acknowledged meanwhile) or does not parse (the
  /// reason in `why`).
  std::optional<QueuedMessage> read(std::uint64_t seq, std::string* why = nullptr) const;
  /// Every queued message, oldest first.  Files that do not parse are skipped and named in
  /// `bad` (when given).
  std::vector<QueuedMessage> pending(std::vector<std::string>* bad = nullptr) const;
  /// Number of queued messages (files named like one).
  std::size_t size() const;
  /// Removes a message durably after its acknowledgement.  False when it was not there.
  bool remove(std::uint64_t seq);

  /// Highest scan id handed to the queue so far (0 = none), kept in the file "scan-high-water";
  /// lets a publisher that starts again queue exactly the scans a kill left unqueued.
  std::uint64_t scan_high_water() const;
  /// Raises it to `id` (never lowers it), durably.
  void raise_scan_high_water(std::uint64_t id);

 private:
  std::filesystem::path path_of(std::uint64_t seq) const;
  std::filesystem::path dir_;
  std::atomic<std::uint64_t> last_seq_{0};
};

}  // namespace errsep::io

#pragma once
// Publishing one machine's results to the plant's MQTT broker, store and forward.
//
//   scan files written locally ──scan_committed()──▶ io::MessageQueue (on disk, fsync'ed)
//                                                         │ publisher thread (this class)
//                                                         ▼
//                                    broker  ◀── PUBLISH QoS 1 ── removed only on PUBACK
//
// The publisher runs on a thread of its own, fed from the results store through the disk queue:
// the sampling threads never see it, and a broker that is down, slow or stopped (SIGSTOP) only
// delays messages (they wait on disk).  A SIGKILL or power cut of errsep loses nothing: a queued
// message stays until acknowledged; a scan committed but not yet queued is found at the next
// start by queue_unpublished() (scan ids above the queue's high-water mark).  Delivery is at
// least once: a message whose PUBACK was lost is sent again, with the same scan id.
//
// Topic tree and payloads: io/mqtt_messages.hpp.  The status topic is retained: the birth
// message on every connect, a new one on every change of the daemon's state, the last will
// {"online":false,"state":"offline"} sent by the broker when the connection dies uncleanly, and
// the same published explicitly on a clean stop.  Commands (cmd/scan, only with commands = true)
// go to the caller's CommandFn, which applies the daemon's refusal rules; every command payload
// gets a reply on cmd/scan/reply (malformed ones too, with the reason, and nothing else happens).
#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "errsep/io/machine_config.hpp"
#include "errsep/io/message_queue.hpp"
#include "errsep/io/mqtt_messages.hpp"
#include "errsep/io/results_store.hpp"

namespace errsep::service {

struct PlantPublisherOptions {
  io::MqttConfig mqtt;              ///< [mqtt] of the machine config
  std::filesystem::path queue_dir;  ///< the disk queue (mqtt.queue_dir, or beside the results)
  std::chrono::milliseconds connect_timeout{3000};            ///< CONNECT to CONNACK
  std::chrono::milliseconds retry_min{200}, retry_max{5000};  ///< reconnect back-off
  int max_inflight = 20;                                      ///< unacknowledged PUBLISHes at once
  bool is_valid(std::string* why = nullptr) const;
};

/// What the publisher did so far (a snapshot).
struct PublisherCounters {
  bool connected = false;
  std::uint64_t connects = 0, connect_failures = 0;
  std::uint64_t published = 0;     ///< PUBLISHes of queued messages sent (re-sends included)
  std::uint64_t acknowledged = 0;  ///< queued messages acknowledged and removed
  std::uint64_t commands = 0, commands_refused = 0;
  std::string last_error;
};

class PlantPublisher {
 public:
  /// The daemon's state for the status topic; called on the publisher thread.  Empty (a
  /// one-shot run such as errsep-scan): the status topic is left alone (no birth, no will).
  using StatusFn = std::function<io::StatusMessage()>;
  /// A well-formed cmd/scan request: accept or refuse (reason); called on the publisher thread.
  using CommandFn = std::function<io::CommandReply(const io::ScanCommand&)>;

  /// Reads the password file and opens the queue.  Throws std::runtime_error naming the file or
  /// setting that is wrong.  Nothing connects before start().
  PlantPublisher(PlantPublisherOptions opts, StatusFn status, CommandFn command = {});
  ~PlantPublisher();  ///< stop()
  PlantPublisher(const PlantPublisher&) = delete;
  PlantPublisher& operator=(const PlantPublisher&) = delete;

  void start();
  /// Gives queued messages up to `grace` to go out, publishes the offline status (retained)
  /// when connected, disconnects cleanly and joins the thread, within about 2 × `grace`.  What is
  /// still queued stays on disk for the next start.
  void stop(std::chrono::milliseconds grace = std::chrono::milliseconds(1000));

  /// Queues the summary of scan `stem` of the results store in `store_dir` (and its alarms) and
  /// raises the queue's high-water mark to `scan_id`.  Thread-safe; call after the scan's files
  /// are on disk.  Throws std::runtime_error when the queue cannot be written.
  void scan_committed(const std::filesystem::path& store_dir, const std::string& stem,
                      std::uint64_t scan_id);
  /// Queues every finished scan of the store whose id is above the queue's high-water mark (a
  /// kill between writing a scan and queuing it).  Returns how many.
  int queue_unpublished(const io::ResultsStore& store);
  /// Queues a message that is not a stored scan's (errsep-scan's summary).  Thread-safe.
  void queue(const std::string& topic_suffix, const std::string& payload);

  /// The status topic is re-read now (the daemon's state changed).
  void wake() noexcept { wake_.store(true); }
  /// Messages waiting on disk.
  std::size_t queued() const { return queue_.size(); }
  PublisherCounters counters() const;
  const io::MessageQueue& message_queue() const noexcept { return queue_; }

 private:
  void run();
  void log(int priority, const std::string& msg) const;

  PlantPublisherOptions opts_;
  std::string password_;
  StatusFn status_fn_;
  CommandFn command_fn_;
  io::MessageQueue queue_;
  std::thread thread_;
  std::atomic<bool> stop_{false}, wake_{false};
  std::atomic<bool> new_messages_{false};  ///< queued by this process since the last look
  std::chrono::milliseconds grace_{1000};
  mutable std::mutex mu_;  // guards counters_
  PublisherCounters counters_;
};

/// The queue directory of a config: mqtt.queue_dir, else "mqtt-queue" beside `results_dir`.
std::filesystem::path default_queue_dir(const io::MqttConfig& mqtt,
                                        const std::filesystem::path& results_dir);

}  // namespace errsep::service

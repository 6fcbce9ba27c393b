#include "errsep/service/plant_publisher.hpp"

#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <map>
#include <set>
#include <stdexcept>

#include "errsep/drivers/mqtt_client.hpp"

namespace errsep::service {
namespace {
constexpr int kErr = 3, kWarning = 4, kInfo = 6;  // sd-daemon(3) priorities
}  // namespace

bool PlantPublisherOptions::is_valid(std::string* why) const {
  auto bad = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (mqtt.machine.empty()) return bad("mqtt.machine is empty");
  if (queue_dir.empty()) return bad("queue_dir is empty");
  if (connect_timeout.count() < 100)
    return bad("connect_timeout = " + std::to_string(connect_timeout.count()) + " ms: < 100");
  if (retry_min.count() < 10 || retry_max < retry_min)
    return bad("retry_min = " + std::to_string(retry_min.count()) + " ms, retry_max = " +
               std::to_string(retry_max.count()) + " ms: need 10 <= retry_min <= retry_max");
  if (max_inflight < 1 || max_inflight > 1000)
    return bad("max_inflight = " + std::to_string(max_inflight) + ": not in 1..1000");
  return true;
}

std::filesystem::path default_queue_dir(const io::MqttConfig& mqtt,
                                        const std::filesystem::path& results_dir) {
  if (!mqtt.queue_dir.empty()) return mqtt.queue_dir;
  const auto parent = results_dir.lexically_normal().parent_path();
  return parent.empty() ? std::filesystem::path("mqtt-queue") : parent / "mqtt-queue";
}

PlantPublisher::PlantPublisher(PlantPublisherOptions opts, StatusFn status, CommandFn command)
    : opts_([&] {
        std::string why;
        if (!opts.is_valid(&why)) throw std::invalid_argument("MQTT publisher: " + why);
        return std::move(opts);
      }()),
      status_fn_(std::move(status)),
      command_fn_(std::move(command)),
      queue_(opts_.queue_dir) {
  if (!opts_.mqtt.password_file.empty()) {
    std::ifstream in(opts_.mqtt.password_file);
    if (!in || !std::getline(in, password_))
      throw std::runtime_error("[mqtt] password_file '" + opts_.mqtt.password_file.string() +
                               "': cannot read the password (first line of the file)");
    while (!password_.empty() && (password_.back() == '\r' || password_.back() == '\n'))
      password_.pop_back();
  }
  for (const auto* f :
       {&opts_.mqtt.tls_ca_file, &opts_.mqtt.tls_cert_file, &opts_.mqtt.tls_key_file})
    if (!f->empty() && ::access(f->c_str(), R_OK) != 0)
      throw std::runtime_error("[mqtt] TLS file '" + f->string() + "' cannot be read");
}

PlantPublisher::~PlantPublisher() {
  stop();
}

void PlantPublisher::start() {
  if (thread_.joinable()) return;
  stop_.store(false);
  thread_ = std::thread([this] { run(); });
}

void PlantPublisher::stop(std::chrono::milliseconds grace) {
  grace_ = grace;
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

void PlantPublisher::log(int priority, const std::string& msg) const {
  const std::string line = "<" + std::to_string(priority) + ">mqtt: " + msg + "\n";
  [[maybe_unused]] const ssize_t n = ::write(2, line.data(), line.size());
}

PublisherCounters PlantPublisher::counters() const {
  std::lock_guard<std::mutex> lock(mu_);
  return counters_;
}

void PlantPublisher::queue(const std::string& topic_suffix, const std::string& payload) {
  queue_.push(opts_.mqtt.topic_root() + "/" + topic_suffix, payload);
  new_messages_.store(true);
}

void PlantPublisher::scan_committed(const std::filesystem::path& store_dir, const std::string& stem,
                                    std::uint64_t scan_id) {
  const io::ScanSummary s = io::summarize_stored_scan(store_dir, stem, opts_.mqtt.machine);
  const std::string root = opts_.mqtt.topic_root();
  queue_.push(root + "/scan/" + stem, io::to_json(s));
  for (const auto& a : io::alarms_for(s, opts_.mqtt.straightness_tolerance_um))
    queue_.push(root + "/alarm", io::to_json(a));
  queue_.raise_scan_high_water(scan_id);
  new_messages_.store(true);
}

int PlantPublisher::queue_unpublished(const io::ResultsStore& store) {
  const std::uint64_t hw = queue_.scan_high_water();
  std::map<std::uint64_t, std::pair<std::string, std::set<std::string>>> scans;
  for (const auto& f : store.list())
    if (f.scan_id > hw) {
      scans[f.scan_id].first = f.stem;
      scans[f.scan_id].second.insert(f.kind);
    }
  int n = 0;
  for (const auto& [id, s] : scans) {
    const auto& [stem, kinds] = s;
    // Finished: a result, or a final raw-incomplete file (a checkpoint of a scan the kill
    // interrupted says in_progress and is no finished scan).  A raw file without its result gets
    // the result from the daemon's recovery, which commits it then.
    bool finished = kinds.count("result") > 0;
    if (!finished && kinds.count("raw-incomplete") && !kinds.count("raw")) {
      try {
        finished = io::summarize_stored_scan(store.dir(), stem, opts_.mqtt.machine).outcome !=
                   "in_progress";
      } catch (const std::exception& e) {
        log(kWarning, "scan " + stem + ": " + e.what());
      }
    }
    if (!finished) continue;
    scan_committed(store.dir(), stem, id);
    ++n;
  }
  if (n > 0) log(kInfo, "queued " + std::to_string(n) + " scans written before the last stop");
  return n;
}

void PlantPublisher::run() {
  const io::MqttConfig& m = opts_.mqtt;
  const std::string root = m.topic_root();
  const std::string status_topic = root + "/status";
  const std::string cmd_topic = root + "/cmd/scan";
  drivers::MqttClientOptions co;
  co.host = m.host;
  co.port = m.port;
  co.client_id = m.effective_client_id();
  co.username = m.username;
  co.password = password_;
  co.tls_ca_file = m.tls_ca_file;
  co.tls_cert_file = m.tls_cert_file;
  co.tls_key_file = m.tls_key_file;
  co.keepalive_s = m.keepalive_s;
  // Without a status source (errsep-scan, a one-shot run) the machine's status topic is left to
  // its daemon: no will, no birth, no offline.
  if (status_fn_) co.will_topic = status_topic;
  io::StatusMessage will;
  will.machine = m.machine;
  will.online = false;
  will.state = "offline";
  will.message = "connection lost (last will)";
  co.will_payload = io::to_json(will);
  co.will_qos = m.qos;
  co.will_retain = true;

  drivers::MqttClient client(co);
  std::map<int, std::uint64_t> inflight;  // message id -> queue seq
  bool acked_since_list = false;          // room in flight: look at the queue again now
  std::set<std::uint64_t> sent, unreadable;
  client.on_ack = [&](int mid) {
    const auto it = inflight.find(mid);
    if (it == inflight.end()) return;  // a status or reply
    acked_since_list = true;
    {
      // Counted before the file goes: whoever sees the queue empty sees every count.
      std::lock_guard<std::mutex> lock(mu_);
      ++counters_.acknowledged;
    }
    try {
      queue_.remove(it->second);
    } catch (const std::exception& e) {
      log(kErr, e.what());
    }
    sent.erase(it->second);
    inflight.erase(it);
  };
  auto reply = [&](const io::CommandReply& r) {
    std::string why;
    if (client.publish(cmd_topic + "/reply", io::to_json(r), m.qos, false, &why) == 0)
      log(kWarning, why);
  };
  client.on_message = [&](const std::string& topic, const std::string& payload) {
    if (topic != cmd_topic) return;
    io::CommandReply r;
    r.machine = m.machine;
    std::string why;
    const auto cmd = io::parse_scan_command(payload, &why);
    if (!cmd) {
      r.reason = "malformed command: " + why;
    } else if (!command_fn_) {
      r.request_id = cmd->request_id;
      r.reason = "commands are not enabled";
    } else {
      r = command_fn_(*cmd);
      r.machine = m.machine;
      r.request_id = cmd->request_id;
    }
    {
      std::lock_guard<std::mutex> lock(mu_);
      ++counters_.commands;
      if (!r.accepted) ++counters_.commands_refused;
    }
    log(r.accepted ? kInfo : kWarning,
        "cmd/scan " + (r.request_id.empty() ? std::string("(no id)") : r.request_id) + ": " +
            (r.accepted ? std::string("accepted") : "refused: " + r.reason));
    reply(r);
  };

  using clock = std::chrono::steady_clock;
  auto retry = opts_.retry_min;
  auto next_attempt = clock::now();
  auto next_status = clock::now();
  auto next_list = clock::now();
  std::string status_key, last_logged_error;
  auto set_connected = [&](bool c, const std::string& err) {
    std::lock_guard<std::mutex> lock(mu_);
    counters_.connected = c;
    if (!err.empty()) counters_.last_error = err;
  };
  auto publish_status = [&](bool force) {
    if (!status_fn_) return;
    io::StatusMessage st = status_fn_();
    st.machine = m.machine;
    st.online = true;
    st.queued = queue_.size();
    const std::string key = st.state + "|" + st.message + "|" + st.last_scan_id;
    if (!force && key == status_key) return;
    std::string why;
    if (client.publish(status_topic, io::to_json(st), m.qos, true, &why) != 0) status_key = key;
  };

  while (!stop_.load()) {
    const auto now = clock::now();
    if (!client.connected()) {
      inflight.clear();
      sent.clear();
      set_connected(false, {});
      if (now < next_attempt) {
        std::this_thread::sleep_for(
            std::min<clock::duration>(next_attempt - now, std::chrono::milliseconds(20)));
        continue;
      }
      std::string why;
      if (client.connect(opts_.connect_timeout, &why, &stop_)) {
        retry = opts_.retry_min;
        last_logged_error.clear();
        {
          std::lock_guard<std::mutex> lock(mu_);
          ++counters_.connects;
          counters_.connected = true;
        }
        log(kInfo, "connected to " + m.host + ":" + std::to_string(m.port) + " as " + co.client_id +
                       ", " + std::to_string(queue_.size()) + " messages queued");
        status_key.clear();
        publish_status(true);  // birth: replaces the retained last will
        if (m.commands && !client.subscribe(cmd_topic, m.qos, &why)) log(kWarning, why);
        next_list = clock::now();
      } else {
        {
          std::lock_guard<std::mutex> lock(mu_);
          ++counters_.connect_failures;
          counters_.last_error = why;
        }
        if (why != last_logged_error)
          log(kWarning,
              why + " (retrying; " + std::to_string(queue_.size()) + " messages wait on disk)");
        last_logged_error = why;
        next_attempt = clock::now() + retry;
        retry = std::min(retry * 2, opts_.retry_max);
      }
      continue;
    }
    if (wake_.exchange(false) || now >= next_status) {
      publish_status(false);
      next_status = now + std::chrono::milliseconds(250);
    }
    // The queue is listed when something was queued here, when acknowledgements made room, or
    // every 100 ms (another process may share the queue).
    if (static_cast<int>(inflight.size()) < opts_.max_inflight &&
        (new_messages_.exchange(false) || acked_since_list || now >= next_list)) {
      next_list = now + std::chrono::milliseconds(100);
      acked_since_list = false;
      for (const std::uint64_t seq : queue_.list()) {
        if (static_cast<int>(inflight.size()) >= opts_.max_inflight) break;
        if (sent.count(seq) || unreadable.count(seq)) continue;
        std::string why;
        const auto msg = queue_.read(seq, &why);
        if (!msg) {
          if (why.find(": gone") == std::string::npos) {
            unreadable.insert(seq);
            log(kErr, why + " (left in the queue, not sent)");
          }
          continue;
        }
        const int mid = client.publish(msg->topic, msg->payload, m.qos, msg->retain, &why);
        if (mid == 0) {
          log(kWarning, why);
          break;
        }
        inflight[mid] = seq;
        sent.insert(seq);
        std::lock_guard<std::mutex> lock(mu_);
        ++counters_.published;
      }
    }
    client.loop(std::chrono::milliseconds(50));
    if (!client.connected()) {
      set_connected(false, client.last_error());
      log(kWarning, client.last_error() + " (" + std::to_string(inflight.size()) +
                        " unacknowledged messages will be sent again)");
      next_attempt = clock::now() + retry;
    }
  }
  // Queued messages get the grace time to go out before the clean stop.
  const auto drain_until = clock::now() + grace_;
  while (client.connected() && !queue_.list().empty() && clock::now() < drain_until) {
    for (const std::uint64_t seq : queue_.list()) {
      if (static_cast<int>(inflight.size()) >= opts_.max_inflight) break;
      if (sent.count(seq) || unreadable.count(seq)) continue;
      const auto msg = queue_.read(seq);
      if (!msg) continue;
      std::string why;
      const int mid = client.publish(msg->topic, msg->payload, m.qos, msg->retain, &why);
      if (mid == 0) break;
      inflight[mid] = seq;
      sent.insert(seq);
    }
    client.loop(std::chrono::milliseconds(20));
  }
  if (client.connected() && !status_fn_) client.disconnect();
  if (client.connected()) {
    // A clean stop: the broker sends no will, so say "offline" ourselves (retained).
    io::StatusMessage st;
    st.machine = m.machine;
    st.online = false;
    st.state = "offline";
    st.message = "stopped";
    st.queued = queue_.size();
    bool acked = false;
    int status_mid = 0;
    auto prev_ack = client.on_ack;
    client.on_ack = [&](int mid) {
      if (mid == status_mid) acked = true;
      prev_ack(mid);
    };
    std::string why;
    status_mid = client.publish(status_topic, io::to_json(st), m.qos, true, &why);
    const auto until = clock::now() + grace_;
    while (status_mid != 0 && !acked && client.connected() && clock::now() < until)
      client.loop(std::chrono::milliseconds(20));
    client.disconnect();
  }
  set_connected(false, {});
}

}  // namespace errsep::service

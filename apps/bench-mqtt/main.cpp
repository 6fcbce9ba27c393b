// errsep-bench-mqtt: figures of the MQTT publishing path (a benchmark app, not a test).
//  1. the cost on the committing thread (the daemon's main loop) of queuing one scan's summary:
//     the JSON plus a durable file (write, fsync, rename, directory fsync);
//  2. messages per second from the disk queue to the broker (QoS 1, each removed on PUBACK);
//  3. latency from queuing to the broker's PUBACK, one message at a time;
//  4. sampling-thread jitter at 1 kHz (4 fake sensors) with no publishing, while publishing, and
//     while publishing to a broker that blocks (SIGSTOP): the publisher runs on its own thread,
//     fed from the disk queue, so the sampler's figures should not move.
// Starts its own Mosquitto on 127.0.0.1 (anonymous, an ephemeral port) unless --port is given.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <numeric>
#include <thread>
#include <vector>

#include "errsep/acq/fake_drivers.hpp"
#include "errsep/acq/sampler.hpp"
#include "errsep/acq/spsc_ring.hpp"
#include "errsep/io/mqtt_messages.hpp"
#include "errsep/service/plant_publisher.hpp"
#include "errsep/version.hpp"

extern char** environ;

namespace {

namespace fs = std::filesystem;
using namespace errsep;
using clk = std::chrono::steady_clock;

double ms_since(clk::time_point t0) {
  return std::chrono::duration<double, std::milli>(clk::now() - t0).count();
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())))];
}

int free_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  ::close(fd);
  return ntohs(a.sin_port);
}

/// A broker of our own on loopback; killed with the bench.
struct Broker {
  pid_t pid = -1;
  fs::path dir;
  int port = 0;
  explicit Broker(const fs::path& d) : dir(d) {
    port = free_port();
    std::ofstream(dir / "mosquitto.conf")
        << "allow_anonymous true\npersistence false\n"
        << (::geteuid() == 0 ? "user root\n" : "") << "listener " << port << " 127.0.0.1\n";
    const std::string conf = (dir / "mosquitto.conf").string();
    const char* argv[] = {"/usr/sbin/mosquitto", "-c", conf.c_str(), nullptr};
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 2, (dir / "mosquitto.log").c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (posix_spawn(&pid, argv[0], &fa, nullptr, const_cast<char**>(argv), environ) != 0)
      throw std::runtime_error("cannot start /usr/sbin/mosquitto (Debian package mosquitto)");
    posix_spawn_file_actions_destroy(&fa);
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
  }
  ~Broker() {
    if (pid > 0) {
      ::kill(pid, SIGCONT);
      ::kill(pid, SIGKILL);
      ::waitpid(pid, nullptr, 0);
    }
  }
};

std::string sample_summary(int i) {
  io::ScanSummary s;
  s.machine = "bench";
  s.scan_id = "20261125T120000Z_scan" + std::to_string(100000 + i);
  s.scan_number = static_cast<std::uint64_t>(i);
  s.started_utc = s.ended_utc = io::utc_now_iso();
  s.trigger = "schedule";
  s.outcome = "complete";
  s.points_measured = "52/52";
  s.straightness_minimum_zone_um = 3.21;
  s.straightness_minimum_zone_U_um = 0.42;
  s.straightness_least_squares_um = 3.4;
  s.straightness_least_squares_U_um = 0.42;
  s.lambda = 0;
  s.sigma_hat_um = 0.05;
  s.solver = "lambda 0 (no L-curve corner), sigma_hat 0.05 um, dof 33";
  s.files = {s.scan_id + ".raw.csv", s.scan_id + ".result.csv"};
  return io::to_json(s);
}

service::PlantPublisherOptions options(const std::string& host, int port, const fs::path& q) {
  service::PlantPublisherOptions o;
  o.mqtt.host = host;
  o.mqtt.port = port;
  o.mqtt.machine = "bench";
  o.mqtt.keepalive_s = 5;
  o.queue_dir = q;
  o.connect_timeout = std::chrono::milliseconds(1000);
  return o;
}

/// 1 kHz sampler with 4 fake sensors for `seconds`, a consumer draining the ring; `during` runs
/// on another thread meanwhile.
acq::SamplerStats sample_for(double seconds, bool realtime,
                             const std::function<void(std::atomic<bool>&)>& during) {
  std::vector<std::unique_ptr<acq::FakeSensor>> sensors;
  std::vector<acq::DisplacementSensor*> ptrs;
  for (int i = 0; i < 4; ++i) {
    sensors.push_back(std::make_unique<acq::FakeSensor>(
        "s" + std::to_string(i),
        [](std::int64_t t) { return 1e-9 * static_cast<double>(t % 1000); }));
    sensors.back()->configure();
    ptrs.push_back(sensors.back().get());
  }
  acq::SpscRing<acq::Sample> ring(65536);
  acq::SamplerOptions so;
  so.rate_hz = 1000;
  if (realtime) {  // as [sampler] realtime = true: SCHED_FIFO 80 and mlockall, if permitted
    so.realtime.fifo_priority = 80;
    so.realtime.lock_memory = true;
  }
  acq::Sampler sampler(ptrs, ring, so);
  std::uint64_t consumed = 0;
  acq::RingConsumer consumer({&ring}, [&](const acq::Sample&) { ++consumed; });
  std::atomic<bool> stop{false};
  consumer.start();
  sampler.start();
  std::thread t([&] { during(stop); });
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  stop.store(true);
  t.join();
  sampler.stop();
  consumer.stop();
  return sampler.stats();
}

void print_jitter(const char* what, const acq::SamplerStats& s) {
  std::printf(
      "  %-44s p50 %6.0f us  p99 %6.0f us  p99.9 %6.0f us  max %7.0f us  missed %llu  "
      "overruns %llu\n",
      what, s.jitter.p50_us, s.jitter.p99_us, s.jitter.p999_us, s.jitter.max_us,
      static_cast<unsigned long long>(s.missed_periods),
      static_cast<unsigned long long>(s.overruns));
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "errsep-bench-mqtt: throughput and latency of MQTT publishing (disk queue to "
      "broker, QoS 1) and the sampling thread's jitter with and without it"};
  app.set_version_flag("--version", std::string(errsep::kVersion));
  std::string host = "127.0.0.1";
  int port = 0, messages = 1000, latency_samples = 50;
  double seconds = 5;
  bool realtime = false;
  app.add_option("--host", host, "broker (with --port; default: start a Mosquitto here)");
  app.add_option("--port", port, "broker port (0 = start a Mosquitto on loopback)")
      ->check(CLI::Range(0, 65535));
  app.add_option("--messages", messages, "messages for the throughput figure")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000000));
  app.add_option("--latency-samples", latency_samples, "single-message round trips")
      ->capture_default_str()
      ->check(CLI::Range(1, 100000));
  app.add_option("--seconds", seconds, "sampling time per jitter condition")
      ->capture_default_str()
      ->check(CLI::Range(0.5, 3600.0));
  app.add_flag("--realtime", realtime,
               "sampling thread with SCHED_FIFO 80 + mlockall, as [sampler] realtime = true "
               "(needs the privilege; a warning otherwise)");
  CLI11_PARSE(app, argc, argv);
  std::signal(SIGPIPE, SIG_IGN);

  try {
    std::string tmpl = (fs::temp_directory_path() / "errsep-bench-mqtt-XXXXXX").string();
    if (!::mkdtemp(tmpl.data())) throw std::runtime_error("mkdtemp failed");
    const fs::path tmp = tmpl;
    std::unique_ptr<Broker> broker;
    if (port == 0) {
      broker = std::make_unique<Broker>(tmp);
      port = broker->port;
      host = "127.0.0.1";
    }
    std::printf("errsep-bench-mqtt %s: broker %s:%d, QoS 1\n", errsep::kVersion, host.c_str(),
                port);

    // 1 + 2: queue `messages` summaries (timed per push), then drain them.
    {
      service::PlantPublisher pub(options(host, port, tmp / "q1"), {});
      std::vector<double> push_ms;
      const std::string payload = sample_summary(0);
      for (int i = 0; i < messages; ++i) {
        const auto t0 = clk::now();
        pub.queue("scan/" + std::to_string(i), sample_summary(i));
        push_ms.push_back(ms_since(t0));
      }
      std::printf(
          "1. queuing a scan summary (%zu bytes, JSON + durable file): mean %.2f ms, "
          "p99 %.2f ms, max %.2f ms\n",
          payload.size(),
          std::accumulate(push_ms.begin(), push_ms.end(), 0.0) /
              static_cast<double>(push_ms.size()),
          percentile(push_ms, 0.99), percentile(push_ms, 1.0));
      const auto t0 = clk::now();
      pub.start();
      while (pub.queued() > 0 && ms_since(t0) < 600000)
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      const double s = ms_since(t0) / 1000;
      pub.stop();
      const auto c = pub.counters();
      std::printf(
          "2. drained %llu messages in %.2f s: %.0f messages/s (each removed on PUBACK; "
          "%llu connects)\n",
          static_cast<unsigned long long>(c.acknowledged), s,
          static_cast<double>(c.acknowledged) / s, static_cast<unsigned long long>(c.connects));
    }
    // 3: one at a time, queue to PUBACK.
    {
      service::PlantPublisher pub(options(host, port, tmp / "q2"), {});
      pub.start();
      std::vector<double> lat;
      for (int i = 0; i < latency_samples; ++i) {
        const auto t0 = clk::now();
        pub.queue("scan/lat" + std::to_string(i), sample_summary(i));
        while (pub.queued() > 0 && ms_since(t0) < 10000)
          std::this_thread::sleep_for(std::chrono::microseconds(200));
        lat.push_back(ms_since(t0));
      }
      pub.stop();
      std::printf(
          "3. added latency per scan, queued to PUBACK (%d samples): median %.1f ms, "
          "p95 %.1f ms, max %.1f ms (the publisher's network loop sleeps up to 50 ms)\n",
          latency_samples, percentile(lat, 0.5), percentile(lat, 0.95), percentile(lat, 1.0));
    }
    // 4: sampler jitter.
    std::printf("4. sampling thread, 1 kHz, 4 fake sensors, %.1f s each, %s:\n", seconds,
                realtime ? "SCHED_FIFO" : "normal priority");
    print_jitter("no publishing", sample_for(seconds, realtime, [](std::atomic<bool>& stop) {
                   while (!stop.load())
                     std::this_thread::sleep_for(std::chrono::milliseconds(5));
                 }));
    std::string note;  // what the publishing thread did, printed after its jitter line
    auto publishing = [&](const fs::path& q, bool block) {
      return [&, q, block](std::atomic<bool>& stop) {
        service::PlantPublisher pub(options(host, port, q), {});
        pub.start();
        if (block && broker) ::kill(broker->pid, SIGSTOP);
        int i = 0;
        while (!stop.load()) {
          pub.queue("scan/j" + std::to_string(i), sample_summary(i));
          ++i;
          std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        pub.stop(std::chrono::milliseconds(100));
        if (block && broker) ::kill(broker->pid, SIGCONT);
        note = "    (" + std::to_string(i) + " scans queued meanwhile, " +
               std::to_string(pub.queued()) + " left on disk at the end)\n";
      };
    };
    print_jitter("publishing 100 scans/s",
                 sample_for(seconds, realtime, publishing(tmp / "q3", false)));
    std::fputs(note.c_str(), stdout);
    if (broker) {
      print_jitter("publishing to a SIGSTOPped broker",
                   sample_for(seconds, realtime, publishing(tmp / "q4", true)));
      std::fputs(note.c_str(), stdout);
    } else
      std::printf("  (blocked-broker condition needs the bench's own broker: omit --port)\n");
    broker.reset();
    std::error_code ec;
    fs::remove_all(tmp, ec);
  } catch (const std::exception& e) {
    std::cerr << "errsep-bench-mqtt: " << e.what() << "\n";
    return 1;
  }
  return 0;
}

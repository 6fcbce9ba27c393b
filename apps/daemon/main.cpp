// errsep-daemon: errsep as a service.  Waits for a trigger (Modbus coil of its register map, a
// rising edge on the machine config's [gpio] start_line, a schedule), runs the configured
// four-sensor or displacement scan ([scan] method) and writes raw data and results durably to the
// results directory.  Runs in the foreground under systemd (Type=notify; see
// config/errsep.service); SIGHUP reloads the machine config between scans, SIGTERM stops the stage,
// writes what was measured and exits.  With an [mqtt] table it also publishes every scan to the
// plant's broker, store and forward (service/plant_publisher.hpp; [mqtt] is read at start only: a
// change needs a restart). After each scan's result folder is committed it makes the report in
// results/<stem>/report/, as errsep-scan does (service/scan_report_job.hpp; --no-report skips it):
// on the main loop, never on a sampling thread; a report that fails is logged and loses none of the
// scan's files.
#include <CLI/CLI.hpp>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <functional>
#include <iostream>
#include <memory>

#include "errsep/acq/daemon.hpp"
#include "errsep/acq/sd_notify.hpp"
#include "errsep/drivers/daemon_backend.hpp"
#include "errsep/drivers/daemon_register_server.hpp"
#include "errsep/io/machine_config.hpp"
#include "errsep/io/unit_dropin.hpp"
#include "errsep/service/displacement_pipeline.hpp"
#include "errsep/service/four_sensor_pipeline.hpp"
#include "errsep/service/plant_publisher.hpp"
#include "errsep/service/scan_report_job.hpp"
#include "errsep/version.hpp"

namespace {
errsep::acq::Daemon* g_daemon = nullptr;
extern "C" void on_stop(int) {
  if (g_daemon) g_daemon->request_stop();  // atomic store + write(2): async-signal-safe
}
extern "C" void on_hup(int) {
  if (g_daemon) g_daemon->request_reload();
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"errsep scan daemon: runs the configured scan on a trigger and keeps every result"};
  app.set_version_flag("--version", std::string(errsep::kVersion));
  app.set_config("--daemon-config", "", "daemon settings (TOML, keys = the long option names)");
  std::string config_path;
  std::string results_dir;
  errsep::drivers::RegisterServerOptions reg;
  int device_port = -1;
  int keep_scans = 0;
  double max_age_days = 0;
  double schedule_s = 0;
  int check_ms = 500, stop_timeout_ms = 5000, gpio_debounce_ms = 20, checkpoint_ms = 1000;
  double min_free_mb = 1.0;
  bool no_separate = false, no_register_map = false, print_dropin = false, no_report = false;
  app.add_option("-c,--config", config_path, "machine config (TOML); re-read on SIGHUP")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--results-dir", results_dir,
                 "results directory; default $STATE_DIRECTORY/results (systemd StateDirectory=), "
                 "else ./results");
  app.add_option("--modbus-host", reg.host, "address of the register map (default loopback)")
      ->capture_default_str();
  app.add_option("--modbus-port", reg.port, "port of the register map (0 = ephemeral)")
      ->capture_default_str()
      ->check(CLI::Range(0, 65535));
  app.add_option("--modbus-max-connections", reg.max_connections,
                 "register map clients at once; beyond it the oldest idle one is closed")
      ->capture_default_str()
      ->check(CLI::Range(1, 4096));
  app.add_option("--modbus-idle-timeout-ms", reg.idle_timeout_ms,
                 "close a register map client after this long without a request")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_flag("--no-register-map", no_register_map, "do not serve the Modbus register map");
  app.add_option("--device-port", device_port,
                 "use this port for every TCP bus whose port is 0 (the port errsep-devsim printed)")
      ->check(CLI::Range(1, 65535));
  app.add_option("--keep-scans", keep_scans,
                 "retention: keep the N scans of highest scan id (0 = keep all)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--max-age-days", max_age_days,
                 "retention: delete scans older than this, by the time in their names; a clock "
                 "before 2024 (no RTC) ages nothing (0 = keep all)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--schedule-s", schedule_s, "also start a scan every this many seconds (0 = off)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--gpio-debounce-ms", gpio_debounce_ms,
                 "GPIO start input ([gpio] start_line of the machine config): ignore rising edges "
                 "this close to the previous one (contact bounce)")
      ->capture_default_str()
      ->check(CLI::Range(0, 10000));
  app.add_option("--check-ms", check_ms, "device check period while idle or in fault")
      ->capture_default_str();
  app.add_option("--stop-timeout-ms", stop_timeout_ms, "SIGTERM: exit within this bound")
      ->capture_default_str();
  app.add_option("--checkpoint-ms", checkpoint_ms,
                 "during a scan, write the raw data measured so far (raw-incomplete) this often")
      ->capture_default_str()
      ->check(CLI::Range(50, 600000));
  app.add_option("--min-free-mb", min_free_mb, "refuse to write with less free disk space")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app.add_flag("--no-separate", no_separate, "write raw data only (no four-sensor result)");
  app.add_flag("--no-report", no_report,
               "make no report after a scan (results/<stem>/report/: evaluation, figures, HTML, "
               "PDF per [report] pdf, compensation tables; errsep-report makes it later)");
  app.add_flag("--print-unit-dropin", print_dropin,
               "print the systemd drop-in that lets the unit reach the Modbus TCP hosts of the "
               "config and the register map's address (the unit allows loopback only), and exit");
  CLI11_PARSE(app, argc, argv);

  try {
    if (print_dropin) {
      std::cout << errsep::io::unit_network_dropin(errsep::io::load_machine_config(config_path),
                                                   no_register_map ? std::string() : reg.host);
      return 0;
    }
    errsep::acq::DaemonOptions opts;
    if (results_dir.empty()) {
      const char* state = std::getenv("STATE_DIRECTORY");
      results_dir = state && *state ? std::string(state) + "/results" : "results";
    }
    opts.results.dir = results_dir;
    opts.results.min_free_bytes = static_cast<std::uint64_t>(min_free_mb * 1048576.0);
    opts.results.retention.keep_scans = keep_scans;
    opts.results.retention.max_age_days = max_age_days;
    opts.schedule_interval_s = schedule_s;
    opts.check_interval = std::chrono::milliseconds(check_ms);
    opts.gpio_debounce = std::chrono::milliseconds(gpio_debounce_ms);
    opts.stop_timeout = std::chrono::milliseconds(stop_timeout_ms);
    opts.checkpoint_interval = std::chrono::milliseconds(checkpoint_ms);
    opts.separate = !no_separate;

    // The result of each scan: the same folder as errsep-scan's, from the same pipeline, with the
    // settings ([refine]) of the config the backend was last built from.
    auto pipeline = std::make_shared<errsep::service::FourSensorPipelineOptions>();
    // The report after each scan, with the settings of the same config ([report], [compensation],
    // [axes]).
    auto report = std::make_shared<errsep::io::ScanReportOptions>();
    opts.write_result_set = [pipeline](const errsep::io::RawFourSensorScan& raw,
                                       const std::filesystem::path& dir) {
      const auto r = errsep::service::FourSensorPipeline(*pipeline).write_result_set(
          raw, dir, std::string("errsep-daemon ") + errsep::kVersion);
      if (!r.separation) throw std::runtime_error(r.error);
      for (const auto& w : r.warnings)
        std::cerr << "<4>" << dir.filename().string() << ": " << w << "\n";
      return *r.separation;
    };

    // A displacement scan ([scan] method = "displacement"): its pipeline, as errsep-scan's.
    auto dpipeline = std::make_shared<errsep::service::DisplacementPipelineOptions>();
    opts.write_displacement_result_set = [dpipeline](const errsep::io::RawDisplacementScan& raw,
                                                     const std::filesystem::path& dir) {
      const auto r =
          errsep::service::DisplacementPipeline(*dpipeline)
              .write_result_set(raw, dir, std::string("errsep-daemon ") + errsep::kVersion);
      if (!r.separation) throw std::runtime_error(r.error);
      return *r.separation;
    };

    // Reads the file again on every call: SIGHUP picks up an edited config.
    auto factory = [config_path, device_port, pipeline, dpipeline,
                    report]() -> std::unique_ptr<errsep::acq::ScanBackend> {
      errsep::io::MachineConfig cfg = errsep::io::load_machine_config(config_path);
      if (device_port > 0) errsep::io::apply_simulator_port(cfg, device_port);
      for (const auto& b : cfg.buses)
        if (b.kind == errsep::io::BusKind::tcp && b.port == 0)
          throw std::runtime_error(config_path + ": bus '" + b.name +
                                   "' has port 0: give --device-port (the simulator's port)");
      *pipeline = errsep::service::pipeline_options(cfg, "");  // [separation], as errsep-scan
      *dpipeline = errsep::service::displacement_pipeline_options(cfg);  // [refine] too
      *report = errsep::service::result_report_options(cfg);
      return std::make_unique<errsep::drivers::DeviceScanBackend>(std::move(cfg));
    };
    // A bad config is an error at start (exit non-zero, message names file:line); later, on
    // SIGHUP, the old config is kept.
    factory();
    // Reports lost to a stop between a scan's commit and its report are made now, before the
    // daemon takes triggers (a few seconds each).
    if (!no_report) errsep::service::remake_missing_reports(opts.results.dir, *report, std::cerr);

    // Plant broker: the publisher thread is fed from the results store through the disk queue,
    // after each scan's files are committed, never from the sampling threads.
    std::unique_ptr<errsep::service::PlantPublisher> publisher;
    std::function<void(std::uint64_t, const std::string&)> publish;
    errsep::acq::Daemon* daemon_ptr = nullptr;  // set before the publisher starts
    if (const auto mqtt = errsep::io::load_machine_config(config_path).mqtt) {
      errsep::service::PlantPublisherOptions po;
      po.mqtt = *mqtt;
      po.queue_dir = errsep::service::default_queue_dir(*mqtt, results_dir);
      auto status = [&daemon_ptr]() {
        errsep::io::StatusMessage m;
        const errsep::acq::DaemonStatus st = daemon_ptr->status();
        m.state = errsep::acq::to_string(st.state);
        m.message = st.message;
        if (const auto f = errsep::io::parse_store_name(st.last_file)) m.last_scan_id = f->stem;
        return m;
      };
      errsep::service::PlantPublisher::CommandFn command;
      if (mqtt->commands)
        command = [&daemon_ptr](const errsep::io::ScanCommand&) {
          errsep::io::CommandReply r;
          std::string why;
          r.accepted = daemon_ptr->trigger(errsep::acq::TriggerSource::mqtt, &why) ==
                       errsep::acq::TriggerReply::accepted;
          r.reason = why;
          return r;
        };
      publisher = std::make_unique<errsep::service::PlantPublisher>(po, status, command);
      publish = [p = publisher.get(), dir = opts.results.dir](std::uint64_t id,
                                                              const std::string& stem) {
        p->scan_committed(dir, stem, id);
      };
      std::cerr << "<6>mqtt: publishing to " << mqtt->host << ":" << mqtt->port << " under "
                << mqtt->topic_root() << "/, queue " << po.queue_dir.string()
                << (mqtt->commands ? ", commands on " + mqtt->topic_root() + "/cmd/scan" : "")
                << "\n";
    }

    // Once a scan's files are on disk (and for each result recovered at start): queued for the
    // broker first (quick), then its report (seconds; on the main loop, which the sampling
    // threads never wait for).
    opts.on_scan_committed = [publish, report, no_report, dir = opts.results.dir](
                                 std::uint64_t id, const std::string& stem) {
      if (publish) publish(id, stem);
      if (!no_report) errsep::service::write_result_report_logged(dir / stem, *report, std::cerr);
    };

    const errsep::acq::SdNotifier notifier;
    if (!notifier.error().empty()) std::cerr << "<4>" << notifier.error() << "\n";
    errsep::acq::Daemon daemon(opts, factory, notifier);
    daemon_ptr = &daemon;
    // The publisher's thread asks the daemon for its status: it stops before the daemon goes,
    // on every way out of this block.
    struct StopFirst {
      errsep::service::PlantPublisher* p;
      ~StopFirst() {
        if (p) p->stop();
      }
    } stop_publisher_first{publisher.get()};
    if (publisher) {
      // Scans written before a kill but not queued (their ids are above the queue's mark).
      publisher->queue_unpublished(errsep::io::ResultsStore(opts.results));
      publisher->start();
    }

    std::unique_ptr<errsep::drivers::DaemonRegisterServer> server;
    if (!no_register_map) {
      server = std::make_unique<errsep::drivers::DaemonRegisterServer>(daemon, reg);
      const int port = server->listen();
      std::cout << "register map listening " << reg.host << ":" << port << std::endl;
      std::cerr << "<6>register map listening " << reg.host << ":" << port << "\n";
      server->start();
    }

    g_daemon = &daemon;
    struct sigaction sa {};
    sa.sa_handler = on_stop;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGTERM, &sa, nullptr);
    sigaction(SIGINT, &sa, nullptr);
    sa.sa_handler = on_hup;
    sigaction(SIGHUP, &sa, nullptr);
    std::signal(SIGPIPE, SIG_IGN);

    const int rc = daemon.run();
    if (server) server->stop();
    if (publisher) publisher->stop();
    g_daemon = nullptr;
    return rc;
  } catch (const std::exception& e) {
    std::cerr << "<3>errsep-daemon: " << e.what() << "\n";
    return 1;
  }
}

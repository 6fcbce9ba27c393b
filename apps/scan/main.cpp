// errsep-scan: run a scan on a machine (or on the embedded device simulator), record the raw data,
// then separate it.
//   errsep-scan --config config/simulator.toml --out out/demo
// Writes OUT/raw.csv (four-sensor: x_mm,m1_um..m4_um,t1_s..t4_s) or OUT/raw_displacement.csv,
// then the result files of the separation (four-sensor: motion.csv, reference.csv, lcurve.csv,
// residuals.csv, summary.txt; displacement: displacement.csv with u, displacement_residuals.csv,
// service/displacement_pipeline.hpp).  --refine (or [refine] enabled = true in the config) also
// runs the refine step of errsep-refine on the four-sensor scan and writes its files to OUT/refine/
// (service/refine_run.hpp). --verify-with TABLE: the scan after a compensation table was loaded
// (the embedded simulator applies it itself), compared with the first scan and the residual the
// table predicts (OUT/verification.txt, .csv; io/verification_report.hpp).  OUT is one result
// set (io/staged_directory.hpp): written beside it and
// moved into place whole at the end, replacing an earlier scan's set whole; a kill at any moment
// leaves the earlier set (or none), and the simulator started for the embedded default dies with
// the scan.  Ctrl-C / SIGTERM: the stages are stopped, the raw data measured so far is written
// marked "complete: false" (the set then holds only it), nothing is separated, exit status 130.
// Then the report (unless --no-report), as errsep-report makes it, into OUT/report/: the ISO 230-1
// evaluation, figures, report.html, report.pdf (headless Chromium; skipped with the reason when
// it is absent) and the compensation tables; it is made after the results are in place, so a
// report that fails loses none of them.
// Exit status: 0 complete, 1 usage/config/device set-up error or a separation that failed (the
// set then holds the raw data alone), 3 scan failed (device fault), 4 the report failed (the
// scan's results are kept), 130 aborted.
#include <unistd.h>
#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <thread>

#include "errsep/acq/scan_runner.hpp"
#include "errsep/core/compensation_verification.hpp"
#include "errsep/core/four_sensor.hpp"
#include "errsep/drivers/device_factory.hpp"
#include "errsep/drivers/scan_devices.hpp"
#include "errsep/drivers/simulator_process.hpp"
#include "errsep/io/cnc/compensation_format.hpp"
#include "errsep/io/default_config.hpp"
#include "errsep/io/machine_config.hpp"
#include "errsep/io/mqtt_messages.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "errsep/io/results_store.hpp"
#include "errsep/io/staged_directory.hpp"
#include "errsep/io/verification_report.hpp"
#include "errsep/service/displacement_pipeline.hpp"
#include "errsep/service/four_sensor_pipeline.hpp"
#include "errsep/service/plant_publisher.hpp"
#include "errsep/service/scan_report_job.hpp"
#include "errsep/version.hpp"

namespace {

std::atomic<bool> g_abort{false};
static_assert(std::atomic<bool>::is_always_lock_free);
extern "C" void on_signal(int) {
  g_abort.store(true);
}  // async-signal-safe

namespace fs = std::filesystem;
using namespace errsep;

/// Progress on the terminal: one rewritten line on a tty, a line per 10 % otherwise.
struct ProgressPrinter {
  bool tty = ::isatty(STDERR_FILENO) != 0;
  int last_decile = -1;
  void operator()(const acq::ScanProgress& p) {
    const int pct = p.points_total ? 100 * p.point / p.points_total : 100;
    if (tty) {
      std::fprintf(stderr, "\r  %-16s point %4d/%-4d %3d%%  x = %8.3f mm  m = %10.4f um   ",
                   p.phase.c_str(), p.point, p.points_total, pct, p.x_mm,
                   p.values_um.empty() ? 0.0 : p.values_um.front());
      if (p.point == p.points_total) std::fputc('\n', stderr);
    } else if (pct / 10 != last_decile) {
      last_decile = pct / 10;
      std::fprintf(stderr, "  %s: point %d/%d (%d%%)\n", p.phase.c_str(), p.point, p.points_total,
                   pct);
    }
    std::fflush(stderr);
  }
};

/// [mqtt]: the scan's summary (and alarms) into the disk queue beside OUT, then up to `wait_s`
/// to deliver it; what is left stays queued for the next run (or the daemon sharing the queue).
void publish_summary(const io::MqttConfig& mqtt, io::ScanSummary s, const fs::path& out,
                     double wait_s) {
  service::PlantPublisherOptions po;
  po.mqtt = mqtt;
  po.queue_dir = service::default_queue_dir(mqtt, out);
  service::PlantPublisher pub(po, {});  // no status: the machine's status topic is the daemon's
  s.machine = mqtt.machine;
  pub.queue("scan/" + s.scan_id, io::to_json(s));
  for (const auto& a : io::alarms_for(s, mqtt.straightness_tolerance_um))
    pub.queue("alarm", io::to_json(a));
  pub.start();
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(wait_s);
  while (pub.queued() > 0 && std::chrono::steady_clock::now() < until)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  pub.stop(std::chrono::milliseconds(200));
  const auto left = pub.queued();
  std::cout << "mqtt: " << mqtt.topic_root() << "/scan/" << s.scan_id << ": "
            << (left == 0
                    ? std::string("delivered")
                    : std::to_string(left) + " messages left queued in " + po.queue_dir.string() +
                          " (" + pub.counters().last_error + "); sent by the next run")
            << "\n";
}

std::vector<double> vec(const Eigen::VectorXd& v) {
  return {v.data(), v.data() + v.size()};
}

/// --verify-with: the second scan (this one) against the first and the table applied between.
void verify(const core::FourSensorResult& res, const io::MachineConfig& cfg, const fs::path& table,
            const fs::path& before_dir, const fs::path& out, const fs::path& shown_out) {
  const io::ControllerTable applied = io::read_compensation_file(table);
  std::string warning;
  const core::MachineError before = io::read_machine_error(before_dir, cfg.axes, &warning);
  if (!warning.empty()) std::cerr << "warning: " << warning << "\n";
  const core::MachineError after =
      core::machine_error(vec(res.x_mm), vec(res.S_um), vec(res.u_S_um), cfg.axes);
  const auto r =
      core::verify_compensation(before, after, [&](double p) { return applied.apply_um(p); });
  const io::VerificationInfo info{cfg.axes.symbol(), fs::absolute(table).string(),
                                  fs::absolute(before_dir).string(), 2.0};
  io::write_verification(out, r, info);
  std::cout << io::verification_text(r, info)
            << "verification: " << (shown_out / "verification.txt").string() << ", "
            << (shown_out / "verification.csv").string() << "\n";
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "errsep-scan: run a four-sensor or displacement-method scan on the machine of a config "
      "(the embedded default starts the device simulator itself), write the raw CSV, then "
      "separate it."};
  app.set_version_flag("--version", std::string("errsep ") + errsep::kVersion);
  std::string config_path, out_dir, method, devsim;
  std::string gauge;
  int averages = 0, settle_ms = -1;
  bool no_separate = false, refine = false;
  std::string refine_reference, verify_table, before_dir;
  double mqtt_wait_s = 10;
  bool no_mqtt = false, no_report = false, no_pdf = false;
  app.add_option("-c,--config", config_path,
                 "machine config (TOML); default: config/simulator.toml of this errsep (its "
                 "source tree, or share/errsep/config/ when installed), from any directory");
  app.add_option("-o,--out", out_dir, "output directory (default: [scan] output_dir)");
  app.add_option("--method", method, "four_sensor, displacement or both (default: [scan] method)")
      ->check(CLI::IsMember({"four_sensor", "displacement", "both"}));
  app.add_option("--averages", averages, "K readings per point (default: [scan] averages)")
      ->check(CLI::Range(1, 100000));
  app.add_option("--settle-ms", settle_ms, "settling time per point (default: [scan] settle_ms)")
      ->check(CLI::Range(0, 600000));
  app.add_option("--devsim", devsim,
                 "device simulator executable for an embedded config (default: errsep-devsim "
                 "next to this program)");
  std::string scan2_order;
  app.add_option("--scan2-order", scan2_order,
                 "displacement method: the order scan 2 reads its points in, forward (the paper) "
                 "or backward (a linear drift of the workpiece sensor shows; default: [scan] "
                 "scan2_order)")
      ->check(CLI::IsMember({"forward", "backward"}));
  auto* no_sep = app.add_flag("--no-separate", no_separate, "record the raw scan only");
  app.add_flag("--refine", refine,
               "after the four-sensor separation, run the refine step (as errsep-refine) and write "
               "its report and refined results to OUT/refine/; after a displacement separation, "
               "its loop (refine/displacement_refine.csv, refine/displacement.csv)")
      ->excludes(no_sep);
  app.add_option("--refine-reference", refine_reference,
                 "reference trace CSV (x_mm,S_um[,gamma_urad] or x_mm,f_um) for the refine step's "
                 "comparison; implies --refine")
      ->excludes(no_sep)
      ->check(CLI::ExistingFile);
  app.add_option("--gauge", gauge,
                 "curvature gauge of the separation, as errsep-separate (default: [separation] "
                 "gauge, else reference): reference (the reference surface has no bow; exact), "
                 "sensor_stage (the sensor stage's zero-adjustment values have no quadratic "
                 "part), paper_eq12")
      ->check(CLI::IsMember(core::curvature_gauge_names()));
  app.add_option("--mqtt-wait-s", mqtt_wait_s,
                 "[mqtt] in the config: wait this long for the broker to take the scan's summary "
                 "(what is not delivered stays queued on disk for the next run)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 3600.0));
  app.add_flag("--no-mqtt", no_mqtt, "do not publish, even with [mqtt] in the config");
  auto* no_rep =
      app.add_flag("--no-report", no_report,
                   "do not make the report (OUT/report/: evaluation, figures, HTML, PDF, "
                   "compensation tables; errsep-report OUT --subdir report makes it later)");
  app.add_flag("--no-pdf", no_pdf, "make the HTML report but no PDF (default: [report] pdf, true)")
      ->excludes(no_rep);
  app.add_option("--verify-with", verify_table,
                 "measure - compensate - verify: the compensation table now loaded in the "
                 "controller (any errsep format; the embedded simulator applies it itself); the "
                 "four-sensor scan is compared with the first scan and the predicted residual, "
                 "written to OUT/verification.txt and .csv")
      ->excludes(no_sep)
      ->check(CLI::ExistingFile);
  app.add_option("--before", before_dir,
                 "result directory of the first scan (default: the directory whose "
                 "compensation/ holds the --verify-with table)")
      ->check(CLI::ExistingDirectory);
  CLI11_PARSE(app, argc, argv);

  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  ::sigaction(SIGINT, &sa, nullptr);
  ::sigaction(SIGTERM, &sa, nullptr);

  int exit_code = 0;
  try {
    if (config_path.empty()) config_path = io::default_config_file().string();
    io::MachineConfig cfg = io::load_machine_config(config_path);
    if (averages > 0) cfg.scan.averages = averages;
    if (settle_ms >= 0) cfg.scan.settle_ms = settle_ms;
    if (!scan2_order.empty())
      cfg.scan.scan2_order = core::displacement_scan_order_from_string(scan2_order);
    // [separation] of the config, the command line over it.
    if (!gauge.empty()) cfg.separation.gauge = *core::curvature_gauge_from_string(gauge);
    io::ScanMethod m = cfg.scan.method;
    if (method == "four_sensor") m = io::ScanMethod::four_sensor;
    if (method == "displacement") m = io::ScanMethod::displacement;
    if (method == "both") m = io::ScanMethod::both;
    const fs::path out = out_dir.empty() ? cfg.scan.output_dir : fs::path(out_dir);
    if (!verify_table.empty()) {
      if (m == io::ScanMethod::displacement)
        throw std::invalid_argument(
            "--verify-with needs a four-sensor scan (--method four_sensor)");
      (void)io::read_compensation_file(verify_table);  // a table that cannot be read: stop now
      if (before_dir.empty()) before_dir = io::result_dir_of_table(verify_table).string();
      if (before_dir.empty())
        throw std::invalid_argument("--verify-with " + verify_table +
                                    ": not in a result directory's compensation/; give the first "
                                    "scan's result directory with --before");
    }
    // Every scan's options are checked before anything starts: a plan the runner cannot run
    // (scan.plan = rezeroed needs the sensor re-zeroed by hand) is refused before the device
    // simulator starts, a stage moves or a staging folder exists.
    for (const auto kind : {acq::ScanKind::four_sensor, acq::ScanKind::displacement})
      if ((kind == acq::ScanKind::four_sensor) ? m != io::ScanMethod::displacement
                                               : m != io::ScanMethod::four_sensor)
        (void)acq::scan_options_from_config(cfg, kind);  // throws naming the key
    // The result folder is one set: everything is written into a staging folder beside it and
    // moved into place in one rename at the end (io/staged_directory.hpp), so that a kill at any
    // moment leaves the earlier result whole (or no folder), never files of two runs.  What is
    // reported as written is reported once it is in place.
    io::StagedDirectory stage(out, {"scan", std::string("errsep-scan ") + kVersion, false, {}});
    if (const std::string swept = io::describe_swept(stage.swept()); !swept.empty())
      std::cout << swept << "\n";
    const fs::path work = stage.dir();
    std::vector<std::string> written;
    std::optional<io::ScanSummary> summary;  // published once the set is in place
    bool report_due = false;                 // a separation's results are in the set

    // The embedded default: no machine, start the device simulator and talk to it.
    std::unique_ptr<drivers::SimulatorProcess> sim;
    if (cfg.simulator.embedded) {
      const fs::path exe = devsim.empty() ? drivers::default_devsim_path() : fs::path(devsim);
      if (exe.empty())
        throw std::runtime_error(
            "config " + config_path +
            " uses the embedded device simulator, but errsep-devsim was not found next to this "
            "program; give its path with --devsim");
      std::vector<std::string> sim_args;
      if (!verify_table.empty()) sim_args = {"--compensation", verify_table};
      sim = std::make_unique<drivers::SimulatorProcess>(exe, config_path, sim_args);
      io::apply_simulator_port(cfg, sim->port());
      std::cout << "device simulator: pid " << sim->pid() << ", listening " << sim->host() << ":"
                << sim->port() << "\n";
    }

    std::optional<drivers::Devices> dev;  // destroyed (buses closed) before the simulator stops
    dev.emplace(drivers::make_devices(cfg));
    dev->configure();

    std::vector<acq::ScanKind> kinds;
    if (m != io::ScanMethod::displacement) kinds.push_back(acq::ScanKind::four_sensor);
    if (m != io::ScanMethod::four_sensor) kinds.push_back(acq::ScanKind::displacement);
    for (const auto kind : kinds) {
      const auto opts = acq::scan_options_from_config(cfg, kind);
      const auto devices = drivers::scan_devices(*dev, cfg, kind);
      std::cout << "scan: " << acq::to_string(kind) << " on " << config_path << " ("
                << opts.averages << " readings per point at " << opts.sampler.rate_hz << " Hz)\n";
      ProgressPrinter printer;
      acq::ScanHooks hooks;
      hooks.progress = [&printer](const acq::ScanProgress& p) { printer(p); };
      hooks.abort = &g_abort;
      const auto started = std::chrono::system_clock::now();
      auto res = acq::run_scan(devices, opts, hooks);
      if (printer.tty && res.counts.points_done != res.counts.points_total)
        std::fputc('\n', stderr);

      // The raw record first, whatever happened: complete or not, it is kept.
      const fs::path raw_name =
          kind == acq::ScanKind::four_sensor ? "raw.csv" : "raw_displacement.csv";
      const fs::path raw_file = out / raw_name;  // where it will be, named in the results
      const std::vector<std::pair<std::string, std::string>> meta = {
          {"config", fs::absolute(config_path).string()}, {"run_id", stage.run_id()}};
      if (res.four_sensor) {
        res.four_sensor->metadata.insert(res.four_sensor->metadata.begin(), meta.begin(),
                                         meta.end());
        io::write_raw_four_sensor_csv(work / raw_name, *res.four_sensor);
      } else {
        res.displacement->metadata.insert(res.displacement->metadata.begin(), meta.begin(),
                                          meta.end());
        io::write_raw_displacement_csv(work / raw_name, *res.displacement);
      }
      std::cout << res.brief_report() << "\n";
      written.push_back("raw data: " + raw_file.string() +
                        (res.complete() ? "" : " (marked incomplete)"));
      for (const auto& s : res.samplers)
        if (!s.realtime.all_ok())
          std::cerr << "warning: real-time set-up: " << s.realtime.brief() << "\n";

      if (!res.complete()) {
        std::cerr << "errsep-scan: scan " << acq::to_string(res.outcome) << ": " << res.stop_reason
                  << "; stages stopped; nothing separated\n";
        exit_code = res.outcome == acq::ScanRunOutcome::aborted ? 130 : 3;
        break;
      }
      if (no_separate) continue;
      try {
        if (res.four_sensor) {
          // The four-sensor pipeline (service/four_sensor_pipeline.hpp), as errsep-daemon and
          // errsep-separate run it: separation, optional refine, the result files.
          auto po = service::pipeline_options(cfg, gauge);
          if (refine || !refine_reference.empty()) po.refine = true;
          if (!refine_reference.empty()) po.refine_reference = refine_reference;
          const auto run = service::FourSensorPipeline(po).separate(
              *res.four_sensor, work, work / raw_name, raw_file.string(), stage.run_id());
          const core::FourSensorResult& sep = *run.separation;
          std::cout << "separation: " << sep.brief_report() << "\n";
          if (run.refine) std::cout << run.refine->brief_report() << "\n";
          for (const auto& w : run.warnings)
            std::cerr << "warning: " << w << "\n";
          io::ScanSummary s;
          // A scan id unique per machine: the start time and this process.
          s.scan_id = io::ResultsStore::stem(started, 0).substr(0, 16) + "_scan-app-" +
                      std::to_string(::getpid());
          s.started_utc = io::utc_iso(started);
          s.ended_utc = io::utc_now_iso();
          s.trigger = "manual";
          s.outcome = "complete";
          s.points_measured = std::to_string(res.counts.points_done) + "/" +
                              std::to_string(res.counts.points_total);
          s.files = {"raw.csv",    "motion.csv",    "reference.csv",
                     "lcurve.csv", "residuals.csv", "summary.txt"};
          io::add_separation(s, sep);
          summary = s;
          if (!verify_table.empty()) verify(sep, cfg, verify_table, before_dir, work, out);
          written.push_back(
              "results: " + out.string() +
              "/ (motion.csv, reference.csv, lcurve.csv, residuals.csv, summary.txt)");
          if (run.refine) {
            written.push_back("refine: " + (out / "refine").string() +
                              "/ (refine_report.txt, refine_steps.csv, refined motion.csv, "
                              "reference.csv, ...)");
            io::ScanSummary::Refine rf;
            rf.model_complete = run.refine->model_complete();
            rf.verdict = run.refine->brief_report();
            rf.model = run.refine->model_name;
            for (std::size_t k = 1; k < run.refine->steps.size(); ++k)
              rf.steps.push_back(run.refine->steps[k].effect);
            summary->refine = rf;
            summary->files.push_back("refine/refine_report.txt");
          }
        } else {
          // The displacement pipeline (service/displacement_pipeline.hpp), as errsep-daemon and
          // errsep-separate-displacement run it: the joint estimate with its u, the residuals.
          // --refine / [refine] enabled: its loop too (refine/displacement_refine.csv).
          auto dpo = service::displacement_pipeline_options(cfg);
          if (refine) dpo.refine = true;
          const auto run = service::DisplacementPipeline(dpo).separate(
              work, work / raw_name, raw_file.string(), stage.run_id());
          std::cout << "separation (displacement method): " << run.brief_report() << "\n";
          written.push_back("results: " + out.string() + "/ (" + service::kDisplacementResultCsv +
                            ", " + service::kDisplacementResidualsCsv +
                            (run.refine ? std::string(", ") + service::kDisplacementRefineCsv +
                                              ", " + service::kDisplacementRefinedCsv
                                        : std::string()) +
                            ")");
        }
        report_due = true;
      } catch (const std::exception& e) {
        // The measurements are kept: the set holds the raw files alone (no result is better than
        // some of them), and the error is reported.
        for (const auto& entry : fs::directory_iterator(work))
          if (entry.path().filename().string().rfind("raw", 0) != 0) fs::remove_all(entry.path());
        written.erase(
            std::remove_if(written.begin(), written.end(),
                           [](const std::string& l) { return l.rfind("raw data: ", 0) != 0; }),
            written.end());
        std::cerr << "errsep-scan: separation failed: " << e.what() << "; the raw data is kept\n";
        summary.reset();
        report_due = false;
        exit_code = 1;
        break;
      }
    }
    dev.reset();  // close the buses before the simulator goes
    if (sim) sim->stop();
    stage.commit();  // the whole set, in one rename
    for (const auto& line : written)
      std::cout << line << "\n";
    // The report, from the result set now in place: a report that fails loses no result.
    if (report_due && !no_report) {
      const io::ScanReportOptions ro = service::result_report_options(cfg, !no_pdf);
      std::cout << "report: evaluating " << out.string() << " into " << (out / "report").string()
                << "/ (figures, HTML" << (ro.pdf_printer ? ", PDF" : "")
                << ", compensation tables)\n";
      try {
        service::print_report_outcome(io::write_scan_report(out, ro), out, std::cout, std::cerr);
      } catch (const std::exception& e) {
        std::cerr << "errsep-scan: the report failed: " << e.what() << "; the scan's results are "
                  << "kept in " << out.string() << " (errsep-report " << out.string()
                  << " --subdir report makes the report again)\n";
        exit_code = 4;
      }
    }
    // Store and forward: the result is on disk first, then its summary goes to the queue.
    if (summary && cfg.mqtt && !no_mqtt) publish_summary(*cfg.mqtt, *summary, out, mqtt_wait_s);
  } catch (const std::exception& e) {
    std::cerr << "errsep-scan: " << e.what() << "\n";
    return 1;
  }
  return exit_code;
}

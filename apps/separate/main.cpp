// errsep-separate: four-sensor separation (Zhao 2019) of a recorded raw scan CSV.
//   errsep-separate RAW.csv --out DIR
// Reads x_mm,m1_um..m4_um (one row per slide position, one column per configuration), writes
// DIR/motion.csv, reference.csv, lcurve.csv, residuals.csv, summary.txt.
#include <CLI/CLI.hpp>
#include <cmath>
#include <iostream>

#include "errsep/core/four_sensor.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/machine_config.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "errsep/io/staged_directory.hpp"
#include "errsep/service/four_sensor_pipeline.hpp"
#include "errsep/version.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "errsep-separate: separate the reference profile f(x), straightness S(x) and tilt "
      "gamma(x) from a four-sensor raw scan (Zhao et al. 2019).\n"
      "Input CSV: columns x_mm,m1_um,m2_um,m3_um,m4_um (one row per slide position x_n, "
      "one column per sensor configuration), and the geometry: metadata lines '# dx_mm: 5', "
      "'# s2: 1', '# s3: 1', '# s4: 5', '# N: 69' or --s2 --s3 --s4 (--dx-mm)."};
  app.set_version_flag("--version", std::string("errsep ") + errsep::kVersion);
  std::string input, out_dir = "out/separate", rule = "reml", gauge = "reference",
                     prior = "second_difference", estimator = "posterior";
  double lambda = 0;
  int s2 = 0, s3 = 0, s4 = 0;
  double dx = 0;
  errsep::core::FourSensorOptions opts;
  app.add_option("raw_csv", input, "raw four-sensor scan CSV")->required();
  app.add_option("--out", out_dir, "result directory")->capture_default_str();
  app.add_option("--dx-mm", dx, "sampling interval, mm (default: from metadata or x_mm)");
  app.add_option("--s2", s2, "spacing s2 in samples (default: from metadata; required without)");
  app.add_option("--s3", s3, "spacing s3 in samples (default: from metadata; required without)");
  app.add_option("--s4", s4, "spacing s4 in samples (default: from metadata; required without)");
  app.add_option("--estimator", estimator,
                 "posterior (a prior on f, posterior covariance; default) or paper_system (the "
                 "paper's augmented system, for comparison)")
      ->capture_default_str();
  app.add_option("--prior", prior,
                 "prior on the reference profile f: second_difference (smooth f; default), "
                 "identity (the paper's Eq. 17), none (unregularised, exact covariance)")
      ->capture_default_str();
  std::string config;
  app.add_option("-c,--config", config,
                 "machine config: its [separation] table (gauge, lambda_rule, lambda_min, "
                 "lambda_max, fixed_lambda, threads) sets the defaults; options given here "
                 "override it")
      ->check(CLI::ExistingFile);
  app.add_option("--rule", rule, "lambda rule: reml, gcv, lcurve, discrepancy, fixed, ls")
      ->capture_default_str();
  app.add_option("--lambda", lambda, "lambda for --rule fixed");
  app.add_option(
         "--gauge", gauge,
         "curvature gauge: reference (f has no bow, exact; default), sensor_stage (the stage's "
         "zero-adjustment values have no quadratic part, weak row), paper_eq12")
      ->check(CLI::IsMember(errsep::core::curvature_gauge_names()))
      ->capture_default_str();
  app.add_option("--lcurve-points", opts.lcurve.count, "lambda values on the L-curve grid")
      ->capture_default_str();
  app.add_option("--threads", opts.lcurve.threads,
                 "threads for the lambda search (same result; faster for long scans)")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  CLI11_PARSE(app, argc, argv);

  try {
    if (!config.empty()) {
      // [separation] of the machine config, the command line over it.
      const auto sc = errsep::io::load_machine_config(config).separation;
      if (!app.count("--gauge")) gauge = errsep::core::to_string(sc.gauge);
      if (!app.count("--rule") && sc.lambda_rule) rule = errsep::core::to_string(*sc.lambda_rule);
      if (!app.count("--lambda")) lambda = sc.fixed_lambda;
      if (!app.count("--threads")) opts.lcurve.threads = sc.threads;
      opts.lcurve.lambda_min = sc.lambda_min;
      opts.lcurve.lambda_max = sc.lambda_max;
    }
    const auto r = errsep::core::lambda_rule_from_string(rule);
    if (!r) throw std::invalid_argument("--rule: unknown rule '" + rule + "'");
    const auto g = errsep::core::curvature_gauge_from_string(gauge);
    if (!g) throw std::invalid_argument("--gauge: unknown gauge '" + gauge + "'");
    const auto p = errsep::core::penalty_from_string(prior);
    if (!p) throw std::invalid_argument("--prior: unknown prior '" + prior + "'");
    const auto e = errsep::core::estimator_from_string(estimator);
    if (!e) throw std::invalid_argument("--estimator: unknown estimator '" + estimator + "'");
    opts.rule = *r;
    opts.gauge = *g;
    opts.penalty = *p;
    opts.estimator = *e;
    opts.fixed_lambda = lambda;
    opts.search.threads = opts.lcurve.threads;
    std::string why;
    if (!opts.is_valid(&why)) throw std::invalid_argument("options: " + why);

    const auto scan = errsep::io::read_raw_four_sensor_csv(input);
    if (!scan.geometry) {
      // The spacings are a property of the scan, not of errsep: without them in the file or
      // on the command line the separation would solve the wrong system (Zhao 2019 Eq. 2).
      std::string missing;
      for (const auto& [name, value] : {std::pair{"--s2", s2}, {"--s3", s3}, {"--s4", s4}})
        if (value <= 0) missing += (missing.empty() ? "" : ", ") + std::string(name);
      if (!missing.empty())
        throw errsep::io::CsvError(
            input, 0,
            "no sensor spacings: the file has no geometry metadata ('# dx_mm:', '# s2:', "
            "'# s3:', '# s4:', '# N:' lines) and " +
                missing +
                " not given; give the spacings of this scan in samples (errsep does not assume "
                "them)");
    }
    errsep::core::FourSensorConfig cfg;
    if (scan.geometry) cfg = *scan.geometry;
    if (s2 > 0) cfg.s2 = s2;
    if (s3 > 0) cfg.s3 = s3;
    if (s4 > 0) cfg.s4 = s4;
    const auto P = static_cast<int>(scan.positions());
    if (P < 2) throw errsep::io::CsvError(input, 0, "need at least 2 slide positions");
    if (dx > 0)
      cfg.dx_mm = dx;
    else if (!scan.geometry)
      cfg.dx_mm = scan.x_mm[1] - scan.x_mm[0];
    // The rows must lie on the dx grid: x_n = x_0 + n·dx.
    for (int n = 0; n < P; ++n) {
      const double expect = scan.x_mm[0] + n * cfg.dx_mm;
      if (std::abs(scan.x_mm[static_cast<size_t>(n)] - expect) > 1e-6 * std::max(1.0, cfg.dx_mm))
        throw errsep::io::CsvError(input, scan.line_of(static_cast<std::size_t>(n)),
                                   "x_mm of data row " + std::to_string(n + 1) + " is " +
                                       std::to_string(scan.x_mm[static_cast<size_t>(n)]) +
                                       ", expected " + std::to_string(expect) +
                                       " (rows must be on the dx = " + std::to_string(cfg.dx_mm) +
                                       " mm grid)");
    }
    cfg.N = P + cfg.s2 + cfg.s3 + cfg.s4;
    if (!cfg.is_valid(&why))
      throw errsep::io::CsvError(input, 0,
                                 "spacings s = (" + std::to_string(cfg.s2) + ", " +
                                     std::to_string(cfg.s3) + ", " + std::to_string(cfg.s4) +
                                     ") with " + std::to_string(P) + " rows: " + why);
    // All result files appear together or not at all, as one result set replacing an earlier
    // one whole (io/staged_directory.hpp); the files are the four-sensor pipeline's
    // (service/four_sensor_pipeline.hpp), as errsep-scan and errsep-daemon write them.
    errsep::io::StagedDirectory stage(
        out_dir, {"separate", std::string("errsep-separate ") + errsep::kVersion, false, {}});
    if (const std::string swept = errsep::io::describe_swept(stage.swept()); !swept.empty())
      std::cout << swept << "\n";
    errsep::io::RawFourSensorScan in = scan;
    in.geometry = cfg;
    errsep::service::FourSensorPipelineOptions po;
    po.separation = opts;
    errsep::service::FourSensorPipelineResult run;
    try {
      run = errsep::service::FourSensorPipeline(po).separate(in, stage.dir(), input, input,
                                                             stage.run_id());
    } catch (const std::exception& err) {  // name the file the data came from
      throw std::runtime_error(input + ": " + err.what());
    }
    const errsep::core::FourSensorResult& res = *run.separation;
    stage.commit();
    std::cout << res.brief_report() << "\n"
              << "results written to " << out_dir << "/ (motion.csv, reference.csv, lcurve.csv, "
              << "residuals.csv, summary.txt)\n";
    for (const auto& w : run.warnings)
      std::cerr << "warning: " << w << "\n";
    if (res.lambda_fallback == errsep::core::LambdaFallback::no_regularisation)
      std::cerr << "note: the L-curve has no corner (the unregularised solution is not "
                   "dominated by noise); no regularisation applied\n";
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "errsep-separate: " << e.what() << "\n";
    return 1;
  }
}

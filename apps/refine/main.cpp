// errsep-refine: close the loop on a recorded four-sensor scan (issue 5): fit Zhao 2019 Eq. (1),
// test what it leaves unexplained, add the effects of the library that the residual asks for,
// re-solve, and report the error before and after.
//   errsep-refine RAW.csv --out DIR [--truth TRUTH.csv] [--reference REF.csv]
// Writes DIR/refine_steps.csv, refine_report.txt, the refined motion.csv, reference.csv,
// lcurve.csv, residuals.csv, summary.txt (model named in their metadata) and, with --reference,
// reference_comparison.csv.  Exit status 0 also when the residual is not white (the report says
// so); 1 for bad input or options, and then DIR is left as it was.
#include <CLI/CLI.hpp>
#include <iostream>

#include "errsep/io/machine_config.hpp"
#include "errsep/io/staged_directory.hpp"
#include "errsep/service/refine_run.hpp"
#include "errsep/version.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "errsep-refine: find what the four-sensor model (Zhao 2019 Eq. 1) leaves unexplained in a "
      "raw scan, add the effects of the library the residual calls for (sensor positioning PE1, "
      "gain, drift, slide positioning PE2, periodic, ...), and report the result before and "
      "after.\n"
      "Input: a raw four-sensor CSV from errsep-scan or errsep-simulate (x_mm,m1_um..m4_um "
      "[,t1_s..t4_s]).  --truth: x_mm,f_um,S_um,gamma_urad on the reference grid (simulations); "
      "--reference: an independent trace x_mm,S_um[,gamma_urad] or x_mm,f_um (interferometer, "
      "CMM) on its own grid."};
  app.set_version_flag("--version", std::string("errsep ") + errsep::kVersion);
  std::string input, out_dir = "out/refine", truth, reference, gauge, config;
  errsep::io::GeometryOverrides geo;
  errsep::service::RefineRunOptions opts;
  app.add_option("raw_csv", input, "raw four-sensor scan CSV")->required();
  app.add_option("--out", out_dir, "result directory")->capture_default_str();
  app.add_option("--truth", truth, "truth CSV of a simulated scan (errors against it per step)");
  app.add_option("--reference", reference,
                 "reference trace CSV (error before/after after best-fit alignment)");
  app.add_option("--dx-mm", geo.dx_mm, "sampling interval, mm (default: from metadata or x_mm)");
  app.add_option("--s2", geo.s2, "spacing s2 in samples (default: from metadata)");
  app.add_option("--s3", geo.s3, "spacing s3 in samples (default: from metadata)");
  app.add_option("--s4", geo.s4, "spacing s4 in samples (default: from metadata)");
  app.add_option("--gauge", gauge,
                 "curvature gauge of the separations, as errsep-separate (default: [separation] "
                 "gauge of --config, else reference)")
      ->check(CLI::IsMember(errsep::core::curvature_gauge_names()));
  app.add_option("-c,--config", config,
                 "machine config: its [separation] (gauge, lambda rule and range, threads) and "
                 "[refine] alpha set the defaults; options given here override them")
      ->check(CLI::ExistingFile);
  app.add_option("--alpha", opts.refine.alpha, "significance of one step (family-wise)")
      ->capture_default_str();
  app.add_option("--whiteness-alpha", opts.refine.residual.alpha,
                 "level of the residual whiteness test")
      ->capture_default_str();
  app.add_option("--max-effects", opts.refine.max_effects, "stop after this many additions")
      ->capture_default_str();
  app.add_option("--mc-samples", opts.refine.residual.mc_samples,
                 "Monte-Carlo draws of the whiteness test")
      ->capture_default_str();
  app.add_option("--speed-mm-per-s", opts.refine.speed_mm_per_s,
                 "slide speed for scan-order times when the CSV has no t1_s..t4_s")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  try {
    // [separation] and [refine] of the machine config, the command line over them.
    errsep::io::SeparationConfig separation;
    if (!config.empty()) {
      const auto cfg = errsep::io::load_machine_config(config);
      separation = cfg.separation;
      if (!app.count("--alpha")) opts.refine.alpha = cfg.refine.alpha;
    }
    if (!gauge.empty()) separation.gauge = *errsep::core::curvature_gauge_from_string(gauge);
    opts.refine.solve = separation.options();
    if (!truth.empty()) opts.truth_csv = truth;
    if (!reference.empty()) opts.reference_csv = reference;
    const auto run = errsep::service::run_refine(input, out_dir, opts, geo);
    if (const std::string swept = errsep::io::describe_swept(run.swept); !swept.empty())
      std::cout << swept << "\n";
    std::cout << run.text << "\nwritten:";
    for (const auto& f : run.files)
      std::cout << " " << f.filename().string();
    std::cout << " in " << out_dir << "/\n";
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "errsep-refine: " << e.what() << "\n";
    return 1;
  }
}

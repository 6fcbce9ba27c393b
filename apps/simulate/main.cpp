// errsep-simulate: the simulation platform of Zhao 2019 section 3 as a command: simulate a
// four-sensor scan of the paper's Example 1 (or 2), write it as a raw CSV, separate it, write the
// results and print how far they are from the truth.
#include <CLI/CLI.hpp>
#include <iostream>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/four_sensor_sequence_simulation.hpp"
#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/four_sensor_result_csv.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "errsep/io/reference_csv.hpp"
#include "errsep/io/staged_directory.hpp"
#include "errsep/service/four_sensor_pipeline.hpp"
#include "errsep/version.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "errsep-simulate: simulated four-sensor scan (Zhao 2019 Example 1/2), separated; "
      "writes DIR/raw.csv and the result files, prints errors against the truth."};
  app.set_version_flag("--version", std::string("errsep ") + errsep::kVersion);
  std::string out_dir = "out/simulate";
  double sigma = 0.1;
  std::uint64_t seed = 1;
  int example = 1, k = 3;
  bool pe1 = false, pe2 = false;
  std::string noise_on = "sensors";
  std::string plan = "single";
  std::vector<double> drift_um_per_s, thermal_um;
  double thermal_tau_s = 40.0;
  errsep::core::FourSensorConfig cfg;
  app.add_option("--out", out_dir, "output directory")->capture_default_str();
  app.add_option("--sigma-um", sigma, "sensor noise standard deviation, um")->capture_default_str();
  app.add_option("--seed", seed, "random seed")->capture_default_str();
  app.add_option("--example", example, "paper example: 1 (Eq. 23) or 2 (Eq. 24)")
      ->check(CLI::IsMember({1, 2}))
      ->capture_default_str();
  app.add_option("--k", k, "harmonic order of Example 2")->capture_default_str();
  app.add_option("--noise-on", noise_on,
                 "where the noise enters: sensors (each reading m_i, the physics) or combined "
                 "(each combined output g = C m of Eq. 9 and each m_i, the model under which the "
                 "paper's section-3 figures come out; the g are written to DIR/combined.csv)")
      ->check(CLI::IsMember({"sensors", "combined"}))
      ->capture_default_str();
  app.add_flag("--pe1", pe1,
               "sensor positioning error PE1: the sensor misses each spacing by +12, -15, +20 um "
               "(D = 5.012, 4.985, 25.02 mm at the default geometry)");
  app.add_flag("--pe2", pe2, "slideway positioning error PE2 (Eq. 20)");
  app.add_option("--plan", plan,
                 std::string("scan plan (order of the traverses, core/scan_sequence.hpp): ") +
                     errsep::core::scan_sequence_kind_names() +
                     "; other than single, raw.csv records every traverse")
      ->capture_default_str();
  app.add_option("--drift-um-per-s", drift_um_per_s,
                 "undeclared linear drift a_c * t of the sensor in configurations 1..4, um/s "
                 "(four values; records the scan as a sequence)")
      ->expected(4);
  app.add_option("--thermal-um", thermal_um,
                 "undeclared thermal drift A_c * (1 - exp(-t/tau)) in configurations 1..4, um "
                 "(four values; records the scan as a sequence)")
      ->expected(4);
  app.add_option("--thermal-tau-s", thermal_tau_s, "time constant of --thermal-um, s")
      ->capture_default_str();
  app.add_option("--dx-mm", cfg.dx_mm, "sampling interval, mm")->capture_default_str();
  app.add_option("--N", cfg.N, "number of reference points")->capture_default_str();
  app.add_option("--s2", cfg.s2)->capture_default_str();
  app.add_option("--s3", cfg.s3)->capture_default_str();
  app.add_option("--s4", cfg.s4)->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  try {
    std::string why;
    if (!cfg.is_valid(&why)) throw std::invalid_argument("configuration: " + why);
    const auto truth = example == 1 ? errsep::core::zhao2019_example1(cfg)
                                    : errsep::core::zhao2019_example2(cfg, k);
    errsep::core::FourSensorSimOptions so;
    so.sigma_um = sigma;
    so.seed = seed;
    const bool combined = noise_on == "combined";
    if (combined) so.noise_model = errsep::core::NoiseModel::combined_outputs;
    if (pe1) so.actual_spacing_mm = errsep::core::zhao2019_pe1_spacing_mm(cfg);
    if (pe2) so.positioning_error_um = errsep::core::zhao2019_pe2_um(cfg.travel_mm());
    auto sim = errsep::core::simulate_four_sensor(cfg, truth, so);

    errsep::io::RawFourSensorScan raw;
    raw.complete = true;
    raw.geometry = cfg;
    raw.x_mm.assign(sim.x_mm.data(), sim.x_mm.data() + sim.x_mm.size());
    // A scan sequence (issue 16 item 2): every traverse with its time and direction, and the
    // undeclared time effects on top; the separation below takes each configuration's first
    // traverse (m1..m4), the refine step of errsep-separate/errsep-scan the whole sequence.
    const auto kind = errsep::core::scan_sequence_kind_from_string(plan);
    const bool sequence = kind != errsep::core::ScanSequenceKind::single ||
                          !drift_um_per_s.empty() || !thermal_um.empty();
    if (sequence && (combined || pe1 || pe2))
      throw std::invalid_argument(
          "--plan/--drift-um-per-s/--thermal-um simulate the sensors' noise and no PE1/PE2: "
          "drop --noise-on combined, --pe1, --pe2");
    std::optional<errsep::core::SequenceSimData> seq_sim;
    if (sequence) {
      const auto seq = errsep::core::ScanSequence::make(kind, cfg);
      errsep::core::SequenceSimOptions qo;
      qo.sigma_um = sigma;
      qo.seed = seed;
      for (std::size_t c = 0; c < drift_um_per_s.size(); ++c)
        qo.effects.drift_um_per_s[c] = drift_um_per_s[c];
      for (std::size_t c = 0; c < thermal_um.size(); ++c)
        qo.effects.thermal_um[c] = thermal_um[c];
      qo.effects.thermal_tau_s = thermal_tau_s;
      seq_sim = errsep::core::simulate_four_sensor_sequence(cfg, truth, seq, qo);
      errsep::io::set_sequence(raw, seq, seq_sim->m_um, seq_sim->t_s);
      for (int j = 0; j < 4; ++j)
        for (Eigen::Index n = 0; n < sim.m_um.rows(); ++n)
          sim.m_um(n, j) = raw.m_um[static_cast<size_t>(j)][static_cast<size_t>(n)];
    } else {
      for (int j = 0; j < 4; ++j)
        for (Eigen::Index n = 0; n < sim.m_um.rows(); ++n)
          raw.m_um[static_cast<size_t>(j)].push_back(sim.m_um(n, j));
    }
    // DIR is one result set, replacing an earlier simulation's whole (io/staged_directory.hpp).
    errsep::io::StagedDirectory stage(
        out_dir, {"simulate", std::string("errsep-simulate ") + errsep::kVersion, false, {}});
    if (const std::string swept = errsep::io::describe_swept(stage.swept()); !swept.empty())
      std::cout << swept << "\n";
    const std::filesystem::path work = stage.dir();
    raw.metadata = {{"source", "errsep-simulate example " + std::to_string(example)},
                    {"run_id", stage.run_id()},
                    {"sigma_um", std::to_string(sigma)},
                    {"seed", std::to_string(seed)},
                    {"noise_on", noise_on}};
    errsep::io::write_raw_four_sensor_csv(work / "raw.csv", raw);
    // The truth on the reference grid, as errsep-refine --truth reads it.
    errsep::io::write_truth_csv(work / "truth.csv", {sim.f_um, sim.S_um, sim.gamma_rad}, cfg,
                                raw.x_mm.front(),
                                {{"source", "errsep-simulate example " + std::to_string(example)},
                                 {"run_id", stage.run_id()}});

    if (combined) {
      errsep::io::CsvTable g;
      g.set_meta("source", "errsep-simulate example " + std::to_string(example));
      g.set_meta("units", "x in mm, combined outputs g = C m (Zhao 2019 Eq. 9) in um");
      g.set_meta("noise_on", noise_on);
      g.add_column("x_mm", raw.x_mm);
      for (int r = 0; r < 4; ++r) {
        std::vector<double> col(static_cast<size_t>(sim.g_um.rows()));
        for (Eigen::Index n = 0; n < sim.g_um.rows(); ++n)
          col[static_cast<size_t>(n)] = sim.g_um(n, r);
        g.add_column("g" + std::to_string(r + 1) + "_um", col);
      }
      g.set_meta("run_id", stage.run_id());
      errsep::io::write_csv(work / "combined.csv", g);
    }
    errsep::core::FourSensorResult res;
    if (sequence) {
      // A scan sequence's result is its fit of every traverse: the four-sensor pipeline's, as
      // errsep-separate, errsep-scan and errsep-daemon write it (service/four_sensor_pipeline).
      auto run = errsep::service::FourSensorPipeline({}).separate(
          raw, work, work / "raw.csv", out_dir + "/raw.csv", stage.run_id());
      res = std::move(*run.separation);
      for (const auto& w : run.warnings)
        std::cerr << "warning: " << w << "\n";
    } else {
      res = combined ? errsep::core::separate_four_sensor_combined(cfg, sim.m_um, sim.g_um)
                     : errsep::core::separate_four_sensor(cfg, sim.m_um);
      errsep::io::write_four_sensor_result(
          work, res, {out_dir + "/raw.csv", "X", "Y", {{"run_id", stage.run_id()}}});
    }
    stage.commit();
    Eigen::VectorXd dS = res.S_um - sim.S_um;
    Eigen::VectorXd dg = res.gamma_rad - sim.gamma_rad;
    dg.array() -= dg.mean();
    std::cout << res.brief_report() << "\n"
              << "truth comparison: max|dS| = " << dS.cwiseAbs().maxCoeff()
              << " um, max|dgamma| (constant removed) = "
              << dg.cwiseAbs().maxCoeff() * errsep::core::kDegPerRad << " deg\n"
              << "written: " << out_dir << "/raw.csv, truth.csv, "
              << (combined ? "combined.csv, " : "")
              << "motion.csv, reference.csv, lcurve.csv, residuals.csv, summary.txt\n";
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "errsep-simulate: " << e.what() << "\n";
    return 1;
  }
}

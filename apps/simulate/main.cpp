// errsep-simulate: the simulation platform of Zhao 2019 section 3 as a command: simulate a
// four-sensor scan of the paper's Example 1 (or 2), write it as a raw CSV, separate it, write the
// results and print how far they are from the truth.  --method displacement: a one-axis
// displacement-method scan (Haramiishi 2024, section 2.3.1) written as errsep-scan writes it
// (raw_displacement.csv), separated by the same pipeline (--refine: its loop), with the truth.
#include <CLI/CLI.hpp>
#include <cmath>
#include <iostream>
#include <sstream>

#include "errsep/core/displacement_simulation.hpp"
#include "errsep/core/four_sensor.hpp"
#include "errsep/core/four_sensor_sequence_simulation.hpp"
#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/four_sensor_result_csv.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "errsep/io/reference_csv.hpp"
#include "errsep/io/staged_directory.hpp"
#include "errsep/service/displacement_pipeline.hpp"
#include "errsep/service/four_sensor_pipeline.hpp"
#include "errsep/version.hpp"

namespace {

/// The undeclared effects of a simulated displacement scan, per sensor: [0] workpiece sensor 1,
/// [1] reference sensor 2.
struct DisplacementEffects {
  std::vector<double> drift_um_per_s, thermal_um;
  double thermal_tau_s = 40.0;
};

double rms_shape(const Eigen::VectorXd& e) {
  return std::sqrt((e.array() - e.mean()).square().mean());
}

/// --method displacement: the scan of Haramiishi 2024 Fig. 5's inputs, as errsep-scan records it
/// (io/raw_scan_csv.hpp), separated by service::DisplacementPipeline, the truth beside it.
int simulate_displacement(const std::string& out_dir, double sigma, std::uint64_t seed,
                          errsep::core::DisplacementScanOrder order, const DisplacementEffects& fx,
                          bool refine) {
  namespace core = errsep::core;
  namespace io = errsep::io;
  core::OneAxisSimOptions so;
  so.workpiece_sensor.noise_sigma_um = sigma;
  so.reference_sensor.noise_sigma_um = sigma;
  so.seed = seed;
  so.reverse_scan2 = order == core::DisplacementScanOrder::backward;
  so.timing.pause_between_scans_s = 2.0;  // the reference piece is traversed between the scans
  if (!fx.drift_um_per_s.empty()) {
    so.workpiece_sensor.drift_um_per_s = fx.drift_um_per_s[0];
    so.reference_sensor.drift_um_per_s = fx.drift_um_per_s[1];
  }
  if (!fx.thermal_um.empty()) {
    so.workpiece_thermal_um = fx.thermal_um[0];
    so.reference_thermal_um = fx.thermal_um[1];
  }
  so.thermal_tau_s = fx.thermal_tau_s;
  const core::OneAxisSimData sim = core::simulate_one_axis(core::haramiishi2024_fig5_truth(), so);

  auto vec = [](const Eigen::VectorXd& v) { return std::vector<double>(v.begin(), v.end()); };
  io::RawDisplacementScan raw;
  raw.complete = true;
  raw.d_mm = so.displacement_mm;
  raw.scan2_order = order;
  raw.x_mm = vec(sim.x_mm);
  raw.s1_scan1_um = vec(sim.s1_1_um);
  raw.s2_scan1_um = vec(sim.s2_1_um);
  raw.s1_scan2_um = vec(sim.s1_2_um);
  raw.s2_scan2_um = vec(sim.s2_2_um);
  raw.t_scan1_s = vec(sim.t1_s);
  raw.t_scan2_s = vec(sim.t2_s);

  io::StagedDirectory stage(
      out_dir, {"simulate", std::string("errsep-simulate ") + errsep::kVersion, false, {}});
  if (const std::string swept = io::describe_swept(stage.swept()); !swept.empty())
    std::cout << swept << "\n";
  const std::filesystem::path work = stage.dir();
  auto num = [](double v) {
    std::ostringstream os;
    os.precision(10);
    os << v;
    return os.str();
  };
  raw.metadata = {{"source", "errsep-simulate displacement (Haramiishi 2024 Fig. 5 inputs)"},
                  {"run_id", stage.run_id()},
                  {"sigma_um", num(sigma)},
                  {"seed", std::to_string(seed)},
                  {"drift_um_per_s_sensor1", num(so.workpiece_sensor.drift_um_per_s)},
                  {"drift_um_per_s_sensor2", num(so.reference_sensor.drift_um_per_s)},
                  {"thermal_um_sensor1", num(so.workpiece_thermal_um)},
                  {"thermal_um_sensor2", num(so.reference_thermal_um)},
                  {"thermal_tau_s", num(so.thermal_tau_s)}};
  const auto raw_csv = work / errsep::service::kDisplacementRawCsv;
  io::write_raw_displacement_csv(raw_csv, raw);
  io::CsvTable truth;
  truth.set_meta("source", "errsep-simulate displacement (Haramiishi 2024 Fig. 5 inputs)");
  truth.set_meta("run_id", stage.run_id());
  truth.set_meta("units", "x in mm, profiles in um");
  truth.add_column("x_mm", raw.x_mm);
  truth.add_column("w_um", vec(sim.w_um));
  truth.add_column("r_um", vec(sim.r_um));
  truth.add_column("m_um", vec(sim.m_um));
  io::write_csv(work / "truth.csv", truth);

  errsep::service::DisplacementPipelineOptions po;
  po.refine = refine;
  const auto run = errsep::service::DisplacementPipeline(po).separate(
      work, raw_csv,
      (std::filesystem::path(out_dir) / errsep::service::kDisplacementRawCsv).string(),
      stage.run_id());
  stage.commit();
  std::cout << run.brief_report() << "\n";
  auto compare = [&](const char* what, const core::OneAxisJointResult& r) {
    const Eigen::VectorXd e = r.estimate.w_um - sim.w_um;
    std::cout << "truth comparison (" << what << "): w error " << rms_shape(e)
              << " um rms (its constant removed, the gauge's)";
    if (r.u_w_um.size() == e.size()) {
      int inside = 0;
      for (Eigen::Index k = 0; k < e.size(); ++k)
        inside += std::abs(e(k) - e.mean()) <= 2 * r.u_w_um(k);
      std::cout << ", " << inside << "/" << e.size() << " points within 2 u(w)";
    }
    std::cout << "\n";
  };
  if (run.separation) compare("separation", *run.separation);
  if (run.refine) compare("refined", run.refine->refined);
  std::cout << "written: " << out_dir << "/raw_displacement.csv, truth.csv";
  for (const auto& f : run.files)
    std::cout << ", " << f;
  std::cout << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "errsep-simulate: simulated four-sensor scan (Zhao 2019 Example 1/2), separated; "
      "writes DIR/raw.csv and the result files, prints errors against the truth.  --method "
      "displacement: a one-axis displacement scan (Haramiishi 2024) as errsep-scan records it."};
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
  double rezero_offset_um = 20.0, nonlinearity_c2_per_um = 0.0, nonlinearity_mid_um = 0.0;
  double hysteresis_um = 0.0;
  std::string method = "four_sensor", scan2_order = "forward";
  bool refine = false;
  errsep::core::FourSensorConfig cfg;
  app.add_option("--out", out_dir, "output directory")->capture_default_str();
  app.add_option("--method", method,
                 "four_sensor (Zhao 2019) or displacement (Haramiishi 2024 one axis, Fig. 5's "
                 "inputs: DIR/raw_displacement.csv as errsep-scan writes it, displacement.csv, "
                 "displacement_residuals.csv, truth.csv)")
      ->check(CLI::IsMember({"four_sensor", "displacement"}))
      ->capture_default_str();
  app.add_option("--scan2-order", scan2_order,
                 "displacement: the order scan 2 reads its points in (forward, the paper, or "
                 "backward: a linear drift of sensor 1 shows)")
      ->check(CLI::IsMember({"forward", "backward"}))
      ->capture_default_str();
  app.add_flag("--refine", refine,
               "displacement: close the loop (refine/displacement_refine.csv, "
               "refine/displacement.csv), as errsep-scan --refine");
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
                 "(four values; records the scan as a sequence); displacement: two values, "
                 "workpiece sensor 1 and reference sensor 2")
      ->expected(2, 4);
  app.add_option("--thermal-um", thermal_um,
                 "undeclared thermal drift A_c * (1 - exp(-t/tau)) in configurations 1..4, um "
                 "(four values; records the scan as a sequence); displacement: two values, "
                 "sensors 1 and 2")
      ->expected(2, 4);
  app.add_option("--thermal-tau-s", thermal_tau_s, "time constant of --thermal-um, s")
      ->capture_default_str();
  app.add_option("--rezero-offset-um", rezero_offset_um,
                 "--plan rezeroed: the offset the sensor is re-zeroed by for the second pass, um")
      ->capture_default_str();
  app.add_option("--nonlinearity-c2-per-um", nonlinearity_c2_per_um,
                 "undeclared sensor non-linearity: it reads u + c2 * (u - mid)^2, u its linear "
                 "reading with the zero shift (records the scan as a sequence), 1/um")
      ->capture_default_str();
  app.add_option("--nonlinearity-mid-um", nonlinearity_mid_um,
                 "mid of --nonlinearity-c2-per-um, um")
      ->capture_default_str();
  app.add_option("--hysteresis-um", hysteresis_um,
                 "undeclared sensor hysteresis h: it reads r - h * sign(dr/dt) (records the scan "
                 "as a sequence; a plan reading a configuration both ways shows it: reversed, "
                 "serpentine), um")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--dx-mm", cfg.dx_mm, "sampling interval, mm")->capture_default_str();
  app.add_option("--N", cfg.N, "number of reference points")->capture_default_str();
  app.add_option("--s2", cfg.s2)->capture_default_str();
  app.add_option("--s3", cfg.s3)->capture_default_str();
  app.add_option("--s4", cfg.s4)->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  try {
    const std::size_t effect_values = method == "displacement" ? 2 : 4;
    for (const auto* v : {&drift_um_per_s, &thermal_um})
      if (!v->empty() && v->size() != effect_values)
        throw std::invalid_argument("--drift-um-per-s and --thermal-um take " +
                                    std::to_string(effect_values) + " values with --method " +
                                    method + " (" +
                                    (effect_values == 2 ? "sensors 1, 2" : "configurations 1..4") +
                                    "), got " + std::to_string(v->size()));
    if (method == "displacement")
      return simulate_displacement(out_dir, sigma, seed,
                                   errsep::core::displacement_scan_order_from_string(scan2_order),
                                   {drift_um_per_s, thermal_um, thermal_tau_s}, refine);
    if (refine || scan2_order != "forward")
      throw std::invalid_argument("--refine and --scan2-order are for --method displacement");
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
                          !drift_um_per_s.empty() || !thermal_um.empty() ||
                          nonlinearity_c2_per_um != 0.0 || hysteresis_um != 0.0;
    if (sequence && (combined || pe1 || pe2))
      throw std::invalid_argument(
          "--plan/--drift-um-per-s/--thermal-um/--nonlinearity-c2-per-um/--hysteresis-um simulate "
          "the sensors' noise and no PE1/PE2: "
          "drop --noise-on combined, --pe1, --pe2");
    std::optional<errsep::core::SequenceSimData> seq_sim;
    if (sequence) {
      const auto seq = errsep::core::ScanSequence::make(kind, cfg, 10.0, 2.0, rezero_offset_um);
      errsep::core::SequenceSimOptions qo;
      qo.sigma_um = sigma;
      qo.seed = seed;
      for (std::size_t c = 0; c < drift_um_per_s.size(); ++c)
        qo.effects.drift_um_per_s[c] = drift_um_per_s[c];
      for (std::size_t c = 0; c < thermal_um.size(); ++c)
        qo.effects.thermal_um[c] = thermal_um[c];
      qo.effects.thermal_tau_s = thermal_tau_s;
      qo.effects.nonlinearity_c2_per_um = nonlinearity_c2_per_um;
      qo.effects.nonlinearity_mid_um = nonlinearity_mid_um;
      qo.effects.hysteresis_um = hysteresis_um;
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

// Issue 16 item 2 end to end: errsep-simulate writes a raw scan that records its scan sequence
// (plan, each traverse's configuration, direction and reading times) with an undeclared linear
// drift; errsep-refine finds in it what the plan can identify, applies only that, says what it
// cannot identify, and the report prints the findings.  The refined S is checked against the
// simulation's truth within the run's own stated u_S.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/iso230.hpp"
#include "errsep/core/refine.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/raw_scan_csv.hpp"
#include "errsep/io/reference_csv.hpp"
#include "support/support.hpp"

using namespace errsep;
using test::TempDir;

namespace {

// Simulates (Example 1 geometry, sigma 0.1 um) with `plan` and an undeclared effect (by default a
// drift in every configuration), then refines; returns the refine folder's sequence_refine.csv.
io::CsvTable simulate_and_refine(
    const TempDir& tmp, const std::string& plan, std::string* log,
    const std::string& effect_args = "--drift-um-per-s 0.02 -0.015 0.025 0.01") {
  const std::string sim = (tmp / plan).string(), ref = (tmp / (plan + "_refined")).string();
  std::string out;
  REQUIRE(test::run_command(test::app_path("simulate").string() + " --out " + sim + " --plan " +
                                plan + " " + effect_args + " --seed 7 2>&1",
                            &out) == 0);
  *log += out;
  REQUIRE(test::run_command(
              test::app_path("refine").string() + " " + sim + "/raw.csv --out " + ref + " 2>&1",
              &out) == 0);
  *log += out;
  const auto raw = io::read_raw_four_sensor_csv(tmp / plan / "raw.csv");
  REQUIRE(raw.sequence);
  CHECK(raw.sequence->plan == plan);
  return io::read_csv(tmp / (plan + "_refined") / "sequence_refine.csv");
}

std::vector<std::string> findings(const io::CsvTable& t) {
  std::vector<std::string> out;
  const int n = std::stoi(t.meta("findings").value_or("0"));
  for (int k = 1; k <= n; ++k)
    out.push_back(t.meta("finding_" + std::to_string(k)).value_or(""));
  for (const auto& line : out)
    UNSCOPED_INFO(line);  // shown with the next failed assertion
  return out;
}

// Points of S (after the constant, line and bow no scan sees) farther than 4 u_S from the
// simulation's truth (u at k = 1, as written).
int outside_4u(const TempDir& tmp, const std::string& plan, const std::vector<double>& S,
               const std::vector<double>& u) {
  const auto raw = io::read_raw_four_sensor_csv(tmp / plan / "raw.csv");
  const auto truth = io::read_truth_csv(tmp / plan / "truth.csv", *raw.geometry, raw.x_mm.front());
  REQUIRE(static_cast<Eigen::Index>(S.size()) == truth.S_um.size());
  Eigen::VectorXd d(truth.S_um.size());
  for (Eigen::Index n = 0; n < d.size(); ++n)
    d(n) = S[static_cast<std::size_t>(n)] - truth.S_um(n);
  d = core::remove_polynomial(d, 2);
  int outside = 0;
  for (Eigen::Index n = 0; n < d.size(); ++n)
    outside += std::abs(d(n)) > 4.0 * u[static_cast<std::size_t>(n)];
  return outside;
}

bool any_starts(const std::vector<std::string>& v, const std::string& prefix) {
  for (const auto& s : v)
    if (s.rfind(prefix, 0) == 0) return true;
  return false;
}

}  // namespace

TEST_CASE("reversed traverses: the drift is identified, S within the stated u_S of the truth") {
  TempDir tmp;
  std::string log;
  const auto t = simulate_and_refine(tmp, "reversed", &log);
  INFO(log);
  const auto f = findings(t);
  CHECK((any_starts(f, "drift identified") || any_starts(f, "thermal drift identified")));
  CHECK_FALSE(any_starts(f, "drift: not identifiable"));
  // The refined S against the truth within the run's own stated u_S.
  CHECK(outside_4u(tmp, "reversed", t.column("S_after_um", "f"), t.column("u_S_after_um", "f")) ==
        0);
  // The refine folder's motion.csv is that refined fit of every traverse (as the scan's own
  // motion.csv), not the single-scan refine of m1..m4.
  const auto motion = io::read_csv(tmp / "reversed_refined" / "motion.csv");
  CHECK(motion.meta("estimator") == std::optional<std::string>("scan_sequence_fit"));
  CHECK(motion.meta("scan_plan") == std::optional<std::string>("reversed"));
  CHECK_THAT(motion.meta("uncertainty_model").value_or(""),
             Catch::Contains("least-squares fit of every traverse"));
  const auto S = motion.column("S_um", "motion.csv"), S_after = t.column("S_after_um", "f");
  REQUIRE(S.size() == S_after.size());
  for (std::size_t n = 0; n < S.size(); ++n)
    CHECK(S[n] == Approx(S_after[n]).margin(1e-6));
  CHECK(outside_4u(tmp, "reversed", S, motion.column("u_S_um", "motion.csv")) == 0);
  // The report prints the findings.
  std::string out;
  REQUIRE(test::run_command(test::app_path("report").string() + " " +
                                (tmp / "reversed_refined").string() + " --subdir report 2>&1",
                            &out) == 0);
  CHECK_THAT(test::read_file(tmp / "reversed_refined" / "report" / "report.html"),
             Catch::Contains("drift identified"));
}

// The serpentine plan (1 forward, 2 back, 3 forward, 4 back, 1 back) as a user runs it: the
// simulator's sensor hysteresis (0.8 um, 8 sigma) on the paper's Example 1 profile is found from
// configuration 1's two directions, the refined S is not worse than before beyond its stated u_S
// (RMS) and within 4 u_S of the truth at every point; the same hysteresis read in one direction
// only (single plan) is said not identifiable.  Example 1's S (8 um amplitude) turns where
// configuration 1's reading is flat: there the hysteresis column's sign is uncertain, S stays
// 0.5-1.6 um off at x 130-175 mm, and u_S carries the sign's uncertainty (without it: u_S
// 0.37-0.42 um there, 4.4 u_S at x = 155 mm).
namespace {
double rms_error(const TempDir& tmp, const std::string& plan, const std::vector<double>& S) {
  const auto raw = io::read_raw_four_sensor_csv(tmp / plan / "raw.csv");
  const auto truth = io::read_truth_csv(tmp / plan / "truth.csv", *raw.geometry, raw.x_mm.front());
  Eigen::VectorXd d(truth.S_um.size());
  for (Eigen::Index n = 0; n < d.size(); ++n)
    d(n) = S[static_cast<std::size_t>(n)] - truth.S_um(n);
  d = core::remove_polynomial(d, 2);
  return std::sqrt(d.squaredNorm() / static_cast<double>(d.size()));
}
double rms(const std::vector<double>& v) {
  double s = 0;
  for (double x : v)
    s += x * x;
  return std::sqrt(s / static_cast<double>(v.size()));
}
}  // namespace

TEST_CASE("serpentine plan: a sensor hysteresis is identified, S within the stated u_S") {
  TempDir tmp;
  std::string log;
  const auto t = simulate_and_refine(tmp, "serpentine", &log, "--hysteresis-um 0.8");
  INFO(log);
  const auto f = findings(t);
  CHECK(any_starts(f, "hysteresis of the sensor"));
  const double before = rms_error(tmp, "serpentine", t.column("S_before_um", "f"));
  const double after = rms_error(tmp, "serpentine", t.column("S_after_um", "f"));
  INFO("S error RMS " << before << " -> " << after << " um");
  CHECK(after <= before + rms(t.column("u_S_after_um", "f")));
  CHECK(outside_4u(tmp, "serpentine", t.column("S_after_um", "f"), t.column("u_S_after_um", "f")) ==
        0);
  // Reading every configuration in one direction, the same hysteresis is said not identifiable.
  const auto ts = simulate_and_refine(tmp, "single", &log, "--hysteresis-um 0.8");
  CHECK_THAT(ts.meta("hysteresis").value_or(""),
             Catch::Contains("hysteresis: not identifiable from this plan (single)"));
}

TEST_CASE("single plan: the drift is detected, said not identifiable, not applied, u_S widened") {
  TempDir tmp;
  std::string log;
  const auto t = simulate_and_refine(tmp, "single", &log);
  INFO(log);
  const auto f = findings(t);
  CHECK(t.meta("added") == std::optional<std::string>("none"));
  CHECK(any_starts(f, "drift: not identifiable from this plan (single)"));
  bool says_how = false;
  for (const auto& line : f)
    says_how = says_how || line.find("Measure with reversed traverses") != std::string::npos;
  CHECK(says_how);
  // Not applied: S unchanged; u_S widened by what the drift could do.
  const auto Sb = t.column("S_before_um", "f"), Sa = t.column("S_after_um", "f");
  const auto ub = t.column("u_S_before_um", "f"), ua = t.column("u_S_after_um", "f");
  for (std::size_t n = 0; n < Sb.size(); ++n) {
    CHECK(Sa[n] == Sb[n]);
    CHECK(ua[n] >= ub[n]);
  }
  CHECK(outside_4u(tmp, "single", Sa, ua) == 0);  // the widened u covers what the drift did
  // A single plan's result is the separation of m1..m4 (as the scan's files): the refine
  // folder's motion.csv is the single-scan refine.
  CHECK(io::read_csv(tmp / "single_refined" / "motion.csv").meta("estimator") !=
        std::optional<std::string>("scan_sequence_fit"));
}

// Issue 16 item 2: the result of a scan sequence is its fit of every traverse.  errsep-separate
// (the four-sensor pipeline, as errsep-scan, the daemon and errsep-simulate) writes motion.csv
// from the sequence fit: S within 4 u_S of the truth, u_S below the single scan's
// (twice the readings), the ISO 230-1 straightness within its U (k = 2) of the truth's
// (checked at 2U: a bound from the run's own uncertainty, as the 4 u_S), the plan named in
// motion.csv, summary.txt and the report.
TEST_CASE("reversed plan with drift: motion.csv is the sequence fit, u_S below the single scan's") {
  TempDir tmp;
  std::string log;
  REQUIRE(test::run_command(test::app_path("simulate").string() + " --out " +
                                (tmp / "reversed").string() +
                                " --plan reversed --drift-um-per-s 0.02 -0.015 0.025 0.01 "
                                "--seed 7 2>&1",
                            &log) == 0);
  CHECK(io::read_csv(tmp / "reversed" / "motion.csv").meta("scan_plan") ==
        std::optional<std::string>("reversed"));
  const auto sep = tmp / "separated";
  REQUIRE(test::run_command(test::app_path("separate").string() + " " +
                                (tmp / "reversed" / "raw.csv").string() + " --out " + sep.string() +
                                " 2>&1",
                            &log) == 0);
  INFO(log);
  const auto motion = io::read_csv(sep / "motion.csv");
  CHECK(motion.meta("scan_plan") == std::optional<std::string>("reversed"));
  // The metadata describe the fit, not the single separation it replaced.
  CHECK(motion.meta("estimator") == std::optional<std::string>("scan_sequence_fit"));
  CHECK(motion.meta("prior") == std::optional<std::string>("none"));
  CHECK_THAT(motion.meta("uncertainty_model").value_or(""),
             Catch::Contains("least-squares fit of every traverse") &&
                 !Catch::Contains("shrinkage bias not included"));
  const auto S = motion.column("S_um", "motion.csv"), u = motion.column("u_S_um", "motion.csv");
  CHECK(outside_4u(tmp, "reversed", S, u) == 0);
  // The single scan: the separation of each configuration's first traverse (m1..m4).
  const auto raw = io::read_raw_four_sensor_csv(tmp / "reversed" / "raw.csv");
  Eigen::MatrixXd m(static_cast<Eigen::Index>(raw.positions()), 4);
  for (Eigen::Index j = 0; j < 4; ++j)
    for (Eigen::Index n = 0; n < m.rows(); ++n)
      m(n, j) = raw.m_um[static_cast<std::size_t>(j)][static_cast<std::size_t>(n)];
  const auto single = core::separate_four_sensor(*raw.geometry, m);
  double u_seq = 0, u_single = 0;
  for (std::size_t n = 0; n < u.size(); ++n) {
    u_seq += u[n] * u[n];
    u_single +=
        single.u_S_um(static_cast<Eigen::Index>(n)) * single.u_S_um(static_cast<Eigen::Index>(n));
  }
  u_seq = std::sqrt(u_seq / static_cast<double>(u.size()));
  u_single = std::sqrt(u_single / static_cast<double>(u.size()));
  std::printf("reversed plan with drift: RMS u_S %.4f um (sequence fit) vs %.4f um (single scan)\n",
              u_seq, u_single);
  CHECK(u_seq < u_single);
  // The ISO 230-1 straightness and its U from the sequence fit's covariance.
  const auto T = motion.meta_number("straightness_minimum_zone_um", "motion.csv");
  const auto U = motion.meta_number("straightness_minimum_zone_U_um", "motion.csv");
  REQUIRE(T);
  REQUIRE(U);
  const auto truth =
      io::read_truth_csv(tmp / "reversed" / "truth.csv", *raw.geometry, raw.x_mm.front());
  const std::vector<double> st(truth.S_um.data(), truth.S_um.data() + truth.S_um.size());
  const double T_true =
      core::evaluate_straightness(raw.x_mm, st, {}, core::ReferenceLine::minimum_zone)
          .straightness_um;
  std::printf("minimum-zone straightness %.4f um, U %.4f um, truth %.4f um\n", *T, *U, T_true);
  CHECK(std::abs(*T - T_true) <= 2.0 * *U);
  CHECK_THAT(test::read_file(sep / "summary.txt"),
             Catch::Contains("scan sequence fit (plan: reversed, 8 traverses"));
  // Issue 16: summary.txt's first line names the sequence fit, not the single separation's
  // lambda rule; residuals.csv holds every reading of every traverse with its direction.
  const std::string summary = test::read_file(sep / "summary.txt");
  const std::string first_line = summary.substr(0, summary.find('\n'));
  CHECK_THAT(first_line, Catch::StartsWith("four-sensor scan sequence fit") &&
                             Catch::Contains("plan reversed, 8 traverses"));
  CHECK_THAT(first_line, !Catch::Contains("least_squares"));
  const auto res = io::read_csv(sep / "residuals.csv");
  CHECK(res.rows.size() == 8 * raw.positions());
  const auto trav = res.column("traverse", "residuals.csv");
  const auto dir = res.column("direction", "residuals.csv");
  const auto rt = res.column("t_s", "residuals.csv");
  int backward = 0;
  for (std::size_t i = 0; i < dir.size(); ++i)
    backward += dir[i] < 0 ? 1 : 0;
  CHECK(backward == static_cast<int>(4 * raw.positions()));  // each configuration once back
  CHECK(*std::max_element(trav.begin(), trav.end()) == 8.0);
  CHECK(*std::max_element(rt.begin(), rt.end()) > 0.0);
  CHECK_THAT(res.meta("units").value_or(""), Catch::Contains("t in s, residual in um"));
  std::string out;
  REQUIRE(test::run_command(
              test::app_path("report").string() + " " + sep.string() + " --subdir report 2>&1",
              &out) == 0);
  CHECK_THAT(test::read_file(sep / "report" / "report.html"),
             Catch::Contains("scan sequence fit (plan: reversed"));
}

// The machine's way: [scan] plan = "reversed" and the device simulator's sensor drifting in
// time; errsep-scan --refine runs the traverses in the plan's order, records them, and its
// result folder's refine/ holds the findings the report prints.
TEST_CASE("errsep-scan with [scan] plan = reversed and a drifting sensor: the drift is found") {
  TempDir tmp;
  std::string t = test::read_file(test::source_dir() / "config" / "simulator.toml");
  auto replace = [&t](const std::string& from, const std::string& to) {
    const auto pos = t.find(from);
    REQUIRE(pos != std::string::npos);
    t.replace(pos, from.size(), to);
  };
  replace("N = 69", "N = 40");  // quick, as the other scan tests
  replace("[scan]\n", "[scan]\nplan = \"reversed\"\n");
  replace("drift_um_per_s = 0.0", "drift_um_per_s = 0.3");
  for (auto pos = t.find("speed_mm_s = "); pos != std::string::npos;
       pos = t.find("speed_mm_s = ", pos + 1)) {
    const auto end = t.find('\n', pos);
    t.replace(pos, end - pos, "speed_mm_s = 2000.0");
  }
  const auto cfg = tmp / "machine.toml";
  { std::ofstream(cfg) << t; }
  const auto out = tmp / "scan";
  std::string log;
  const int rc =
      test::run_command(test::app_path("scan").string() + " --config " + cfg.string() + " --out " +
                            out.string() + " --devsim " + test::app_path("devsim").string() +
                            " --averages 5 --settle-ms 0 --refine --no-pdf 2>&1",
                        &log);
  INFO(log);
  REQUIRE(rc == 0);
  const auto raw = io::read_raw_four_sensor_csv(out / "raw.csv");
  REQUIRE(raw.sequence);
  CHECK(raw.sequence->plan == "reversed");
  CHECK(raw.sequence->traverses.size() == 8);
  const auto s = io::read_csv(out / "refine" / "sequence_refine.csv");
  const auto f = findings(s);
  // refine/ holds the result the scan's files hold (the sequence's refined fit, refined once),
  // with its metadata, not the single-scan refine of m1..m4.
  const auto top = io::read_csv(out / "motion.csv");
  const auto refined = io::read_csv(out / "refine" / "motion.csv");
  CHECK(refined.meta("estimator") == std::optional<std::string>("scan_sequence_fit"));
  CHECK(refined.meta("uncertainty_model") == top.meta("uncertainty_model"));
  CHECK(refined.meta("separation") == top.meta("separation"));
  CHECK(refined.column("S_um", "refine/motion.csv") == top.column("S_um", "motion.csv"));
  CHECK(refined.column("u_S_um", "refine/motion.csv") == top.column("u_S_um", "motion.csv"));
  // The drift is found: identified and applied in 4 of 6 runs by hand; in the others reported
  // as not separable from a non-repeating traverse (nothing applied).  The devsim's timing and
  // noise are not seeded, so the test asserts what every run shows: a finding that names the
  // drift, and never "not identifiable" (the reversed plan identifies it).
  bool names_drift = false;
  for (const auto& line : f)
    names_drift = names_drift || line.find("drift") != std::string::npos;
  CHECK(names_drift);
  CHECK_FALSE(any_starts(f, "drift: not identifiable"));
  CHECK_THAT(test::read_file(out / "report" / "report.html"),
             Catch::Contains("Scan sequence (plan: reversed)"));
}

// Issue 16 item 3 in the loop: a knock recorded in one traverse of a reversed plan (the sensor
// stays knocked for the later traverses) is named by errsep-refine's sequence refine, written to
// sequence_refine.csv (knock_* metadata, u_S_knock_um) and printed by the report; the refined S
// lies within 4 u_S of the simulation's truth.
TEST_CASE(
    "a knock in one traverse of a reversed plan: named in sequence_refine.csv and the report") {
  TempDir tmp;
  std::string log;
  REQUIRE(test::run_command(test::app_path("simulate").string() + " --out " +
                                (tmp / "reversed").string() + " --plan reversed --seed 11 2>&1",
                            &log) == 0);
  auto raw = io::read_raw_four_sensor_csv(tmp / "reversed" / "raw.csv");
  REQUIRE(raw.sequence);
  auto [seq, M] = io::scan_sequence_of(raw);
  const Eigen::MatrixXd t = seq.times_s(*raw.geometry);
  const int K = 4, P = static_cast<int>(M.rows()), n0 = P / 2;  // traverse 5, halfway
  REQUIRE(seq.traverses[K].direction == core::TraverseDirection::forward);
  M.block(n0, K, P - n0, 1).array() += 1.0;
  for (int k = K + 1; k < M.cols(); ++k)
    M.col(k).array() += 1.0;
  io::set_sequence(raw, seq, M, t);
  io::write_raw_four_sensor_csv(tmp / "reversed" / "raw_knocked.csv", raw);
  const auto ref = tmp / "refined";
  REQUIRE(test::run_command(test::app_path("refine").string() + " " +
                                (tmp / "reversed" / "raw_knocked.csv").string() + " --out " +
                                ref.string() + " 2>&1",
                            &log) == 0);
  INFO(log);
  const auto s = io::read_csv(ref / "sequence_refine.csv");
  findings(s);
  CHECK(s.meta("knock_configuration") ==
        std::optional<std::string>(std::to_string(seq.traverses[K].configuration + 1)));
  CHECK(s.meta("knock_removed") == std::optional<std::string>("true"));
  CHECK(outside_4u(tmp, "reversed", s.column("S_after_um", "f"), s.column("u_S_after_um", "f")) ==
        0);
  std::string out;
  REQUIRE(test::run_command(
              test::app_path("report").string() + " " + ref.string() + " --subdir report 2>&1",
              &out) == 0);
  CHECK_THAT(test::read_file(ref / "report" / "report.html"), Catch::Contains("knocked sensor"));
}

// Issue 16 items 2-3 end to end: errsep-simulate --plan rezeroed measures every configuration
// again with the sensor re-zeroed by 40 um (raw.csv states it per traverse); the sensor reads
// u + c2*(u - 18 um)^2 with c2 = 0.002/um (about 3 um at the ends of the readings' range).
// errsep-refine determines c2 from the re-zeroed traverses, corrects the readings, says so in
// sequence_refine.csv, and S ends within 4 u_S of the truth.
TEST_CASE(
    "rezeroed plan: a sensor non-linearity determined, corrected and named by errsep-refine") {
  TempDir tmp;
  const std::string sim = (tmp / "rezeroed").string(), ref = (tmp / "rezeroed_refined").string();
  std::string log;
  REQUIRE(test::run_command(test::app_path("simulate").string() + " --out " + sim +
                                " --plan rezeroed --rezero-offset-um 40 --nonlinearity-c2-per-um "
                                "0.002 --nonlinearity-mid-um 18 --seed 7 2>&1",
                            &log) == 0);
  INFO(log);
  const auto raw = io::read_raw_four_sensor_csv(tmp / "rezeroed" / "raw.csv");
  REQUIRE(raw.sequence);
  REQUIRE(raw.sequence->traverses.size() == 8);
  CHECK(raw.sequence->traverses[4].zero_shift_um == 40.0);
  CHECK(raw.sequence->traverses[3].zero_shift_um == 0.0);
  std::string out;
  REQUIRE(test::run_command(
              test::app_path("refine").string() + " " + sim + "/raw.csv --out " + ref + " 2>&1",
              &out) == 0);
  INFO(out);
  const auto t = io::read_csv(tmp / "rezeroed_refined" / "sequence_refine.csv");
  const auto f = findings(t);
  REQUIRE_FALSE(f.empty());
  CHECK_THAT(f.front(), Catch::StartsWith("sensor non-linearity (not in the effect library)") &&
                            Catch::Contains("the readings corrected"));
  CHECK_FALSE(any_starts(f, "a knocked sensor"));  // the passes' difference is no step
  const auto Sb = t.column("S_before_um", "f"), Sa = t.column("S_after_um", "f");
  CHECK(outside_4u(tmp, "rezeroed", Sa, t.column("u_S_after_um", "f")) == 0);
  const auto truth =
      io::read_truth_csv(tmp / "rezeroed" / "truth.csv", *raw.geometry, raw.x_mm.front());
  auto err = [&](const std::vector<double>& S) {
    Eigen::VectorXd d(truth.S_um.size());
    for (Eigen::Index n = 0; n < d.size(); ++n)
      d(n) = S[static_cast<std::size_t>(n)] - truth.S_um(n);
    return core::remove_polynomial(d, 2).norm() / std::sqrt(static_cast<double>(d.size()));
  };
  std::printf("rezeroed plan, c2 0.002/um: S error %.3f -> %.3f um RMS\n", err(Sb), err(Sa));
  CHECK(err(Sa) <= 0.5 * err(Sb));
}

// [scan] plan = "rezeroed" in a machine config: its second pass needs the sensor re-zeroed by
// hand, which the scan runner cannot do or pause for, so errsep-scan refuses the plan before it
// moves anything: a non-zero exit, an error naming the key and why, and nothing written (no
// result folder, no staging folder beside it).
TEST_CASE("errsep-scan with [scan] plan = rezeroed: refused before moving, nothing written") {
  TempDir tmp;
  std::string t = test::read_file(test::source_dir() / "config" / "simulator.toml");
  const auto pos = t.find("[scan]\n");
  REQUIRE(pos != std::string::npos);
  t.replace(pos, 7, "[scan]\nplan = \"rezeroed\"\n");
  REQUIRE(t.find("single_sensor = true") != std::string::npos);  // else refused for another reason
  const auto cfg = tmp / "machine.toml";
  { std::ofstream(cfg) << t; }
  const auto out = tmp / "scan";
  std::string log;
  const int rc =
      test::run_command(test::app_path("scan").string() + " --config " + cfg.string() + " --out " +
                            out.string() + " --devsim " + test::app_path("devsim").string() +
                            " --averages 5 --settle-ms 0 --refine --no-pdf 2>&1",
                        &log);
  INFO(log);
  CHECK(rc != 0);
  CHECK_THAT(log, Catch::Contains("scan.plan = rezeroed"));
  CHECK_THAT(log, Catch::Contains("re-zeroed by hand"));
  CHECK_FALSE(std::filesystem::exists(out));
  // Nothing beside the config: no result, no staging folder, no raw file.
  std::vector<std::string> left;
  for (const auto& e : std::filesystem::directory_iterator(tmp.path()))
    if (e.path().filename() != "machine.toml") left.push_back(e.path().filename().string());
  for (const auto& name : left)
    UNSCOPED_INFO("left behind: " << name);
  CHECK(left.empty());
}

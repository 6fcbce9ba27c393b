// The scan sequence's refine as CSV (io::sequence_refine_csv) and read back as the report's table
// of findings (io::sequence_findings_table): the hysteresis and knock metadata, u_S_after's parts
// as columns, and the errors a user gets for a file that is not one.
#include <catch2/catch.hpp>
#include <cmath>

#include "errsep/io/csv.hpp"
#include "errsep/io/refine_report.hpp"

using namespace errsep;

namespace {

// A result filled by hand: the format is what is tested here, not the refine (tests/core).
core::SequenceRefineResult hand_result(int P) {
  core::SequenceRefineResult r;
  r.plan = "reversed";
  r.before.S_um = Eigen::VectorXd::LinSpaced(P, 0.0, 1.0);
  r.before.u_S_um = Eigen::VectorXd::Constant(P, 0.05);
  r.after.S_um = Eigen::VectorXd::LinSpaced(P, 0.0, 0.5);
  r.after.u_S_um = Eigen::VectorXd::Constant(P, 0.07);
  r.u_S_declined_um = Eigen::VectorXd::Constant(P, 0.03);
  r.u_S_drift_form_um = Eigen::VectorXd::Zero(P);
  return r;
}

std::vector<double> positions_mm(int P) {
  std::vector<double> x(static_cast<std::size_t>(P));
  for (int n = 0; n < P; ++n)
    x[static_cast<std::size_t>(n)] = 5.0 * n;
  return x;
}

}  // namespace

TEST_CASE("sequence refine csv: a detected hysteresis gives its size, whether applied, and its u") {
  const int P = 7;
  auto r = hand_result(P);
  r.hysteresis.identifiable = true;
  r.hysteresis.detected = true;
  r.hysteresis.applied = false;
  r.hysteresis.h_um = 0.125;
  r.hysteresis.u_h_um = 0.02;
  r.hysteresis.decision = "too poorly determined";
  r.hysteresis.u_S_added_um = Eigen::VectorXd::LinSpaced(P, 0.0, 0.06);
  const io::CsvTable t = io::sequence_refine_csv(r, positions_mm(P));
  CHECK(t.meta("hysteresis_um") == std::optional<std::string>("0.125 +- 0.02"));
  CHECK(t.meta("hysteresis_applied") == std::optional<std::string>("false"));
  CHECK(t.meta("hysteresis_decision") == std::optional<std::string>("too poorly determined"));
  CHECK_FALSE(t.meta("hysteresis"));
  // u_S_after's parts are columns, each P long: the hysteresis's and the declined step's as given.
  const auto uh = t.column("u_S_hysteresis_um");
  REQUIRE(uh.size() == static_cast<std::size_t>(P));
  for (int n = 0; n < P; ++n)
    CHECK(uh[static_cast<std::size_t>(n)] == Approx(r.hysteresis.u_S_added_um(n)).margin(1e-12));
  const auto ud = t.column("u_S_declined_um");
  REQUIRE(ud.size() == static_cast<std::size_t>(P));
  CHECK(ud.front() == Approx(0.03));
  const auto uf = t.column("u_S_drift_form_um");
  REQUIRE(uf.size() == static_cast<std::size_t>(P));
  CHECK(uf.back() == 0.0);
  // The units line names every column's unit.
  REQUIRE(t.meta("units"));
  CHECK(t.meta("units")->find("um") != std::string::npos);
}

TEST_CASE("sequence refine csv: no hysteresis says whether the plan could show one") {
  const int P = 5;
  auto r = hand_result(P);
  SECTION("a plan that reads a configuration both ways, nothing found") {
    r.hysteresis.identifiable = true;
    const io::CsvTable t = io::sequence_refine_csv(r, positions_mm(P));
    CHECK(t.meta("hysteresis") == std::optional<std::string>("none found"));
    CHECK_FALSE(t.meta("hysteresis_um"));
    // Not detected: its column is there, all zero (nothing added to u_S).
    const auto uh = t.column("u_S_hysteresis_um");
    REQUIRE(uh.size() == static_cast<std::size_t>(P));
    for (double v : uh)
      CHECK(v == 0.0);
  }
  SECTION("a plan that reads every configuration one way: the finding says so") {
    r.hysteresis.identifiable = false;
    r.hysteresis.finding = "hysteresis: not identifiable from this plan (closing pass)";
    const io::CsvTable t = io::sequence_refine_csv(r, positions_mm(P));
    CHECK(t.meta("hysteresis") == std::optional<std::string>(r.hysteresis.finding));
  }
  // No knock fitted and none searched for: "none found".
  const io::CsvTable t = io::sequence_refine_csv(r, positions_mm(P));
  CHECK(t.meta("knock") == std::optional<std::string>("none found"));
  CHECK_FALSE(t.meta("knock_x_mm"));
  // Every term of u_S bounded by the data: no u_S_unbounded key.
  CHECK_FALSE(t.meta("u_S_unbounded0"));
}

TEST_CASE("sequence refine csv: a u_S term held at the readings' bound is one key each") {
  const int P = 5;
  auto r = hand_result(P);
  r.unbounded = {"u_S unbounded: thermal drift not determined by this plan; declare a bound (...)"};
  const io::CsvTable t = io::sequence_refine_csv(r, positions_mm(P));
  CHECK(t.meta("u_S_unbounded0") == std::optional<std::string>(r.unbounded[0]));
  CHECK_FALSE(t.meta("u_S_unbounded1"));
}

TEST_CASE("sequence refine csv: the wrong number of positions is refused, naming both counts") {
  const auto r = hand_result(6);
  try {
    (void)io::sequence_refine_csv(r, positions_mm(5));
    FAIL("expected std::invalid_argument");
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    CHECK(what.find("5 positions") != std::string::npos);
    CHECK(what.find("6 values") != std::string::npos);
  }
}

TEST_CASE("sequence refine csv: read back as the findings table, through the file format") {
  const int P = 4;
  auto r = hand_result(P);
  r.report = {"drift: identified (rate 0.01 um/s)", "hysteresis 0.1 +- 0.02 um: not applied"};
  const std::string text = io::format_csv(io::sequence_refine_csv(r, positions_mm(P)));
  const io::CsvTable back = io::parse_csv(text, "sequence_refine.csv");
  const io::HtmlTable h = io::sequence_findings_table(back, "sequence_refine.csv");
  REQUIRE(h.rows.size() == 2);
  CHECK(h.rows[1].front() == r.report[1]);
  CHECK(h.caption.find("reversed") != std::string::npos);

  SECTION("nothing found: one row that says so") {
    r.report.clear();
    const io::CsvTable t = io::sequence_refine_csv(r, positions_mm(P));
    const io::HtmlTable e = io::sequence_findings_table(t, "sequence_refine.csv");
    REQUIRE(e.rows.size() == 1);
    CHECK(e.rows.front().front().find("nothing detected") != std::string::npos);
  }
  SECTION("a finding line missing: CsvError naming it") {
    io::CsvTable t = io::sequence_refine_csv(r, positions_mm(P));
    t.set_meta("findings", "3");
    CHECK_THROWS_WITH(io::sequence_findings_table(t, "sequence_refine.csv"),
                      Catch::Contains("finding_3"));
  }
  SECTION("another file: CsvError saying what it is not") {
    io::CsvTable t = io::sequence_refine_csv(r, positions_mm(P));
    t.set_meta("format", "errsep refine steps");
    CHECK_THROWS_WITH(io::sequence_findings_table(t, "refine_steps.csv"),
                      Catch::Contains("not a sequence refine file"));
  }
}

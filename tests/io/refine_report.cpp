// The refine step table as CSV and text: one row per parameter of each step, the model in the
// metadata, the whiteness verdict in the text.
#include "errsep/io/refine_report.hpp"

#include <catch2/catch.hpp>
#include <cmath>

#include "support/refine_cases.hpp"

using namespace errsep;

TEST_CASE("refine report: CSV rows per parameter, text names the effect and the verdict") {
  const auto c = test::make_refine_case(
      0.02, 11,
      [](core::FourSensorSimOptions& so) {
        so.actual_spacing_mm = std::array<double, 3>{5.8, 4.4, 25.6};
      },
      {}, 3);
  const auto r = core::refine_four_sensor(c.cfg, c.sim.m_um, Eigen::MatrixXd(), {}, &c.truth);
  REQUIRE(r.steps.size() == 2);
  const io::CsvTable t = io::refine_csv(r);
  CHECK(t.rows.size() == 1 + 3);  // base row + three PE1 parameters
  CHECK(t.meta("model") == std::optional<std::string>("zhao2019-eq1+pe1"));
  CHECK(t.meta("step1_parameter2") == std::optional<std::string>("dD4_mm"));
  const auto col = t.column("value");
  CHECK(col[1] == Approx(r.steps[1].parameters(0)));
  const std::string text = io::format_refine_text(r);
  CHECK(text.find("step 1: pe1") != std::string::npos);
  CHECK(text.find("dD2_mm") != std::string::npos);
  CHECK(text.find(r.residual_white() ? "passes the whiteness test" : "NOT white") !=
        std::string::npos);
}

// An effect the library lacks (a 1.5 um bump on traverse 3): the significant candidates fit it
// only with implausible parameters, so they are listed as rejected in the CSV metadata and the
// text, and the verdict is "model incomplete".
TEST_CASE("refine report: implausible candidates are listed as rejected, the model incomplete") {
  const auto c =
      test::make_refine_case(0.02, 21, {}, [](Eigen::MatrixXd& m, const Eigen::MatrixXd&) {
        for (Eigen::Index n = 0; n < m.rows(); ++n) {
          const double x = 5.0 * static_cast<double>(n);
          m(n, 2) += 1.5 * std::exp(-0.5 * std::pow((x - 150.0) / 8.0, 2));
        }
      });
  const auto r = core::refine_four_sensor(c.cfg, c.sim.m_um, Eigen::MatrixXd(), {}, &c.truth);
  REQUIRE(!r.rejected.empty());
  const io::CsvTable t = io::refine_csv(r);
  CHECK(t.meta("model_complete") == std::optional<std::string>("false"));
  for (std::size_t i = 0; i < r.rejected.size(); ++i) {
    const auto status = t.meta("rejected" + std::to_string(i) + "_status");
    REQUIRE(status);
    CHECK(status->rfind("rejected: implausible parameters (", 0) == 0);
    CHECK(t.meta("rejected" + std::to_string(i) + "_effect") ==
          std::optional<std::string>(r.rejected[i].effect));
  }
  const std::string text = io::format_refine_text(r);
  CHECK(text.find("NOT ADDED") != std::string::npos);
  CHECK(text.find("rejected: implausible parameters (") != std::string::npos);
  CHECK(text.find("model is incomplete") != std::string::npos);
}

// GUM propagation for uncorrelated inputs and the thermal-expansion model of Haramiishi et al.
// 2024, Eqs. (30)-(40), on a spec built in code (the shipped TOML config is tested in
// tests/io/budget_config.cpp).
#include "errsep/core/uncertainty_budget.hpp"

#include <catch2/catch.hpp>
#include <cmath>

using namespace errsep::core;

TEST_CASE("GUM: uniform half-width a gives a/sqrt(3), contributions add in quadrature") {
  CHECK(standard_uncertainty(2.0, Distribution::uniform) == Approx(2.0 / std::sqrt(3.0)));
  CHECK(standard_uncertainty(2.0, Distribution::normal) == 2.0);
  const Budget b = combine_uncorrelated({{"a", "", 3.0, 1.0}, {"b", "", 2.0, -2.0}}, "y", "um");
  REQUIRE(b.rows.size() == 2);
  CHECK(b.rows[1].contribution == Approx(4.0));  // |c|·u
  CHECK(b.variance == Approx(25.0));
  CHECK(b.combined == Approx(5.0));
  CHECK(b.rows[0].share == Approx(9.0 / 25.0));
  CHECK(b.rows[0].share + b.rows[1].share == Approx(1.0));
  CHECK_THAT(b.brief_report(), Catch::Contains("largest b 64 %"));
  REQUIRE_THROWS_WITH(combine_uncorrelated({{"bad", "", -1.0, 1.0}}),
                      Catch::Contains("term 'bad'") && Catch::Contains(">= 0"));
}

namespace {

ThermalModel table1_model() {
  ThermalModel m;
  m.coefficients = {{"al", 23.6e-6, 1e-6, Distribution::uniform},
                    {"st", 11.7e-6, 1e-6, Distribution::uniform}};
  m.components = {{"A", 20, 0.033, Distribution::normal, "al"},
                  {"B", 52, 0.046, Distribution::normal, "al"},
                  {"jig", 65, 0.046, Distribution::normal, "al"},
                  {"ref", 10, 0.022, Distribution::normal, "st"}};
  m.temperature = {4.0, 2.0, Distribution::uniform};
  return m;
}

}  // namespace

TEST_CASE("thermal loop x of Eqs. (31)-(34): l_dJx, beta_x, sigma_tx") {
  const ThermalModel m = table1_model();
  const ThermalResult r = evaluate_thermal_loop(
      m, {"x", "sigma_tx", "", {{"A", 1}, {"B", 1}, {"jig", -1}, {"ref", -1}}});
  REQUIRE(r.group_length_mm.size() == 2);
  CHECK(r.group_length_mm[0].first == "al");
  CHECK(r.group_length_mm[0].second == Approx(7.0));  // Eq. (32): 20 + 52 - 65
  // β_x = 23.6e-6·7 mm - 11.7e-6·10 mm = 48.2 nm/K; the paper prints β_x² = 2323.24e-18 m²
  CHECK(r.beta_um_per_K == Approx(0.0482).epsilon(1e-12));
  CHECK(std::pow(r.beta_um_per_K * 1e-6, 2) == Approx(2323.24e-18).epsilon(1e-9));
  // Eq. (34) term by term (m²/K²): 2.9636 (RSS 0.0729 mm; the paper's 0.0739 gives 3.0417)
  // + 16.3333 + 33.3333 + 0.06625
  const double expect_var_beta =
      (23.6e-6 * 23.6e-6 * (0.033 * 0.033 + 2 * 0.046 * 0.046) * 1e-6 + 49e-6 * 1e-12 / 3 +
       100e-6 * 1e-12 / 3 + 11.7e-6 * 11.7e-6 * 0.022e-3 * 0.022e-3);
  CHECK(std::pow(r.sigma_beta_um_per_K * 1e-6, 2) == Approx(expect_var_beta).epsilon(1e-9));
  // Eq. (33): σ_tx² = ΔT² σ_β² + β² σ_t², σ_t = 2/√3
  CHECK(r.sigma_um == Approx(std::sqrt(16 * expect_var_beta * 1e12 + 0.0482 * 0.0482 * 4.0 / 3.0)));
  CHECK(std::round(r.sigma_um * 100) / 100 == Approx(0.06));
  REQUIRE(r.budget.rows.size() == 2 + 4 + 1);  // two coefficient groups, four lengths, ΔT
  CHECK(r.budget.rows.back().symbol == "dT");
}

TEST_CASE("thermal model and budget spec errors name the culprit") {
  ThermalModel m = table1_model();
  REQUIRE_THROWS_WITH(evaluate_thermal_loop(m, {"x", "s", "", {{"nope", 1}}}),
                      Catch::Contains("unknown component 'nope'"));
  REQUIRE_THROWS_WITH(evaluate_thermal_loop(m, {"x", "s", "", {{"A", 2}}}),
                      Catch::Contains("sign 2"));
  m.components[0].coefficient = "titanium";
  std::string why;
  CHECK_FALSE(m.is_valid(&why));
  CHECK_THAT(why, Catch::Contains("component 'A'") && Catch::Contains("titanium"));
  BudgetSpec s;
  s.thermal = table1_model();
  s.terms = {{"t", "", std::nullopt, "missing_loop", Distribution::normal, 1.0}};
  REQUIRE_THROWS_WITH(evaluate_budget(s), Catch::Contains("unknown thermal loop 'missing_loop'"));
  s.terms = {{"t", "", 1.0, "x", Distribution::normal, 1.0}};
  REQUIRE_THROWS_WITH(evaluate_budget(s), Catch::Contains("exactly one"));
}

TEST_CASE("round_sigma_um rounds each term before combining (to reproduce a printed table)") {
  BudgetSpec s;
  s.thermal = table1_model();
  s.terms = {{"a", "", 1.0555, "", Distribution::normal, 1.0},
             {"b", "", 0.3, "", Distribution::uniform, 1.0}};  // 0.3/√3 = 0.1732
  const auto raw = evaluate_budget(s);
  CHECK(raw.budget.variance == Approx(1.0555 * 1.0555 + 0.03));
  s.round_sigma_um = 0.01;
  const auto rounded = evaluate_budget(s);
  CHECK(rounded.budget.variance == Approx(1.06 * 1.06 + 0.17 * 0.17));
}

#pragma once
// Uncertainty budget (GUM, JCGM 100 section 5.1): law of propagation for uncorrelated inputs,
// u_c² = Σ c_i² u_i², with inputs quoted either as a standard deviation (normal) or as the
// half-width a of a uniform (rectangular) interval, u = a/√3.  Plus the thermal-expansion model of
// Haramiishi et al. 2024, section 3.5, Eqs. (30)-(40), and the combination of Eq. (41).
//
// Thermal model, as read here.  A thermal loop is a signed sum of component lengths between a
// sensor and the surface it reads; a temperature change ΔT moves the gap by
//     δ = β·ΔT,   β = Σ_k s_k α_{g(k)} l_k                         (Eqs. 31, 35, 38)
// where g(k) is the expansion-coefficient group of component k.  Components of one group share
// one coefficient (one uncertain input); different groups are independent inputs.  Lengths are
// independent inputs with their tolerance as standard deviation (the paper: "dimensions follow a
// normal distribution"; it uses the IT8 tolerance itself as σ).  Then
//     σ_β² = Σ_g (Σ_{k∈g} s_k l_k)² σ_αg² + Σ_k α_{g(k)}² σ_lk²    (Eqs. 34, 37, 40)
//     σ_δ² = ΔT² σ_β² + β² σ_T²                                    (Eqs. 33, 36, 39)
// with ΔT the temperature change (4 °C) and σ_T its standard uncertainty (uniform, 2/√3 °C).
// Misprints resolved (each checked by reproducing the paper's σ_tx, σ_ty, σ_tt):
//  - Eq. (33), (36): "σ_refx" in the second term is σ_t (the temperature's uncertainty); Eq. (36)
//    also prints σ_βx, β_x for σ_βy, β_y.
//  - Eq. (32) worked value "20 + 50 - 65 = 7": B is 52 mm (Table 1), 20 + 52 - 65 = 7.
//  - σ_ldJx = √(0.033² + 0.046² + 0.046²) is 0.0729 mm, printed "≈ 0.074" and used as 0.0739;
//    we compute the RSS (σ_tx = 0.0628 µm either way).
//  - β_x "= 2323.24×10⁻⁹ m" is β_x² = 2323.24×10⁻¹⁸ m²/K² (β_x = 48.2 nm/K).
//  - "σ_β² ... mm²" is m²/K² (the terms above it are in m²).
//  - l_dJy "= 30 × 52 - 70 = 12": l_C + l_D - h_jigy = 30 + 52 - 70 = 12 mm.
//  - Eq. (39) "(ΔT)² 2σ_βtt 2" is ΔT²·σ_βtt².
//  - Eq. (40) first group "(l_bp² + h_tb² + l_wp²) σ_αst²": h_tb is aluminium (its term is the
//    third one); the steel group is (l_bp² + l_wp² + h_col²) σ_αst², i.e. base plate, workpiece and
//    column have independent steel coefficients (σ_tt = 1.0556 µm; with h_tb it would be 0.78,
//    with one shared steel coefficient 1.01).  σ_htb = RSS of the tolerances of A-E.
//  - The aluminium parts (A-E and both jigs) share one coefficient α_Al (Eq. 34's l_dJx² σ_αAl²;
//    independent coefficients would give σ_tx = 0.21 µm).
//
// Not implemented: the model predictions of Eqs. (42)-(46) (σ_m2x = 0.57, σ_m4y = 3.00,
// σ_mwxe = 1.07, σ_mwye = 9.37 µm from σ_se, σ_rx, σ_ry, σ_tx, σ_ty).  The printed Eq. (46) scales
// the variances by l_xw/l_xs instead of (l_xw/l_xs)²; only that reading gives 1.07 and 9.37
// (GUM gives 2.51 and 21.97 µm), and no reading found gives 0.57 and 3.00 (√(σ_se² + σ_rx² +
// σ_tx²) = 0.33, √(σ_se² + σ_ry² + σ_ty²) = 2.83).  Eq. (41) uses Table 2's measured values.
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace errsep::core {

enum class Distribution {
  normal,   ///< the quoted value is the standard deviation
  uniform,  ///< the quoted value is the half-width a; u = a/√3
};

/// Standard uncertainty of an input quoted as `quoted` with distribution `d`.
double standard_uncertainty(double quoted, Distribution d);
const char* to_string(Distribution d);

struct BudgetTerm {
  std::string symbol;       ///< e.g. "sigma_m2x"
  std::string description;  ///< e.g. "motion error, x-axis"
  double u = 0;             ///< standard uncertainty of the input (its own unit)
  double sensitivity = 1;   ///< c_i = ∂y/∂x_i
};

struct BudgetRow {
  std::string symbol, description;
  double u = 0;             ///< input standard uncertainty
  double sensitivity = 1;   ///< c_i
  double contribution = 0;  ///< |c_i|·u_i, in the output's unit
  double variance = 0;      ///< c_i²·u_i²
  double share = 0;         ///< variance / combined variance (0..1)
};

struct Budget {
  std::string quantity;  ///< e.g. "sigma_w"
  std::string unit;      ///< of contribution / combined, e.g. "um"
  std::vector<BudgetRow> rows;
  double variance = 0;  ///< u_c²
  double combined = 0;  ///< u_c
  std::string brief_report() const;
};

/// GUM law of propagation for uncorrelated inputs.  Throws std::invalid_argument on a negative or
/// non-finite u or a non-finite sensitivity (naming the term).
Budget combine_uncorrelated(const std::vector<BudgetTerm>& terms, std::string quantity = "",
                            std::string unit = "");

// ---- thermal expansion, Eqs. (30)-(40) ---------------------------------------------------------

struct ExpansionCoefficient {
  std::string name;
  double alpha_per_K = 0;                             ///< e.g. 23.6e-6
  double quoted_per_K = 0;                            ///< ± value of Table 1, e.g. 1.0e-6
  Distribution distribution = Distribution::uniform;  ///< paper: uniform, σ = a/√3
};

struct ThermalComponent {
  std::string name;
  double length_mm = 0;
  double tolerance_mm = 0;                           ///< ± value of Table 1
  Distribution distribution = Distribution::normal;  ///< paper: tolerance used as σ
  std::string coefficient;                           ///< name of its ExpansionCoefficient group
};

struct ThermalLoopTerm {
  std::string component;
  double sign = 1.0;  ///< +1 or -1 in the loop
};

struct ThermalLoop {
  std::string name;    ///< e.g. "x"
  std::string symbol;  ///< e.g. "sigma_tx"
  std::string description;
  std::vector<ThermalLoopTerm> terms;
};

struct TemperatureChange {
  double delta_K = 4.0;   ///< ΔT
  double quoted_K = 2.0;  ///< ± value of the temperature's uncertainty
  Distribution distribution = Distribution::uniform;
};

struct ThermalModel {
  std::vector<ExpansionCoefficient> coefficients;
  std::vector<ThermalComponent> components;
  TemperatureChange temperature;
  /// True if names are unique and every value is finite and non-negative where it must be;
  /// otherwise *why says which.
  bool is_valid(std::string* why = nullptr) const;
};

struct ThermalResult {
  std::string name, symbol, description;
  /// Σ_{k∈g} s_k l_k per coefficient group, in order of appearance (e.g. aluminium: l_dJx = 7 mm)
  std::vector<std::pair<std::string, double>> group_length_mm;
  double beta_um_per_K = 0;  ///< β
  double sigma_beta_um_per_K = 0;
  double sigma_um = 0;  ///< σ_δ of Eqs. (33)/(36)/(39)
  Budget budget;        ///< rows: each coefficient group, each length, ΔT
};

/// Evaluates one loop.  Throws std::invalid_argument for an invalid model, an unknown component
/// or coefficient name, or a sign other than ±1.
ThermalResult evaluate_thermal_loop(const ThermalModel& model, const ThermalLoop& loop);

// ---- the combined budget, Eq. (41) ---------------------------------------------------------

struct BudgetTermSpec {
  std::string symbol, description;
  std::optional<double> quoted_um;  ///< a given value (Table 2), or
  std::string thermal_loop;         ///< the name of a thermal loop whose σ_δ is the input
  Distribution distribution = Distribution::normal;
  double sensitivity = 1.0;
};

struct BudgetSpec {
  std::string title;
  std::string quantity = "sigma_w";
  ThermalModel thermal;
  std::vector<ThermalLoop> loops;
  std::vector<BudgetTermSpec> terms;
  /// Round each term's σ to this resolution before combining (0 = no rounding).  Only to
  /// reproduce a published table that combined rounded entries (Haramiishi 2024 Eq. 41 combines
  /// Table 2's two-decimal values: σ_w² = 68.2472 µm²; unrounded σ_tt gives 68.238 µm²).
  double round_sigma_um = 0.0;
};

struct BudgetEvaluation {
  std::vector<ThermalResult> thermal;  ///< one per loop, in spec order
  Budget budget;                       ///< Eq. (41)
};

/// Evaluates every loop and the combined budget.  Throws std::invalid_argument naming the term
/// or loop at fault (unknown loop, neither or both of value/loop given, bad numbers).
BudgetEvaluation evaluate_budget(const BudgetSpec& spec);

}  // namespace errsep::core

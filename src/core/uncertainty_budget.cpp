#include "errsep/core/uncertainty_budget.hpp"

#include <cmath>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>

namespace errsep::core {
namespace {

void fail(const std::string& what) {
  throw std::invalid_argument("uncertainty budget: " + what);
}

std::string num(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

}  // namespace

double standard_uncertainty(double quoted, Distribution d) {
  return d == Distribution::uniform ? quoted / std::sqrt(3.0) : quoted;
}

const char* to_string(Distribution d) {
  return d == Distribution::uniform ? "uniform" : "normal";
}

Budget combine_uncorrelated(const std::vector<BudgetTerm>& terms, std::string quantity,
                            std::string unit) {
  Budget b;
  b.quantity = std::move(quantity);
  b.unit = std::move(unit);
  for (const auto& t : terms) {
    if (!(std::isfinite(t.u) && t.u >= 0))
      fail("term '" + t.symbol + "': standard uncertainty " + num(t.u) +
           " must be finite and >= 0");
    if (!std::isfinite(t.sensitivity))
      fail("term '" + t.symbol + "': sensitivity " + num(t.sensitivity) + " must be finite");
    BudgetRow r;
    r.symbol = t.symbol;
    r.description = t.description;
    r.u = t.u;
    r.sensitivity = t.sensitivity;
    r.contribution = std::abs(t.sensitivity) * t.u;
    r.variance = r.contribution * r.contribution;
    b.variance += r.variance;
    b.rows.push_back(std::move(r));
  }
  b.combined = std::sqrt(b.variance);
  for (auto& r : b.rows)
    r.share = b.variance > 0 ? r.variance / b.variance : 0.0;
  return b;
}

std::string Budget::brief_report() const {
  std::ostringstream s;
  s << quantity << " = " << combined << " " << unit << " (variance " << variance << " " << unit
    << "^2, " << rows.size() << " uncorrelated terms";
  const BudgetRow* top = nullptr;
  for (const auto& r : rows)
    if (!top || r.variance > top->variance) top = &r;
  if (top) s << "; largest " << top->symbol << " " << 100.0 * top->share << " %";
  s << ")";
  return s.str();
}

bool ThermalModel::is_valid(std::string* why) const {
  auto no = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  std::set<std::string> names;
  for (const auto& c : coefficients) {
    if (c.name.empty()) return no("an expansion coefficient has an empty name");
    if (!names.insert(c.name).second) return no("expansion coefficient '" + c.name + "' twice");
    if (!std::isfinite(c.alpha_per_K))
      return no("coefficient '" + c.name + "': alpha " + num(c.alpha_per_K) + " not finite");
    if (!(std::isfinite(c.quoted_per_K) && c.quoted_per_K >= 0))
      return no("coefficient '" + c.name + "': uncertainty " + num(c.quoted_per_K) +
                " must be finite and >= 0");
  }
  names.clear();
  for (const auto& c : components) {
    if (c.name.empty()) return no("a component has an empty name");
    if (!names.insert(c.name).second) return no("component '" + c.name + "' twice");
    if (!(std::isfinite(c.length_mm) && c.length_mm >= 0))
      return no("component '" + c.name + "': length " + num(c.length_mm) + " must be >= 0");
    if (!(std::isfinite(c.tolerance_mm) && c.tolerance_mm >= 0))
      return no("component '" + c.name + "': tolerance " + num(c.tolerance_mm) + " must be >= 0");
    bool found = false;
    for (const auto& k : coefficients)
      found = found || k.name == c.coefficient;
    if (!found)
      return no("component '" + c.name + "': unknown expansion coefficient '" + c.coefficient +
                "'");
  }
  const auto& t = temperature;
  if (!std::isfinite(t.delta_K)) return no("temperature change " + num(t.delta_K) + " not finite");
  if (!(std::isfinite(t.quoted_K) && t.quoted_K >= 0))
    return no("temperature uncertainty " + num(t.quoted_K) + " must be finite and >= 0");
  return true;
}

ThermalResult evaluate_thermal_loop(const ThermalModel& model, const ThermalLoop& loop) {
  std::string why;
  if (!model.is_valid(&why)) fail(why);
  if (loop.terms.empty()) fail("thermal loop '" + loop.name + "' has no components");
  std::map<std::string, const ExpansionCoefficient*> coef;
  for (const auto& c : model.coefficients)
    coef[c.name] = &c;
  std::map<std::string, const ThermalComponent*> comp;
  for (const auto& c : model.components)
    comp[c.name] = &c;

  ThermalResult res;
  res.name = loop.name;
  res.symbol = loop.symbol;
  res.description = loop.description;
  // Σ s_k l_k per coefficient group, in the order groups first appear.
  std::vector<std::string> group_order;
  std::map<std::string, double> group_length_mm;
  std::vector<BudgetTerm> length_terms;
  for (const auto& t : loop.terms) {
    const auto it = comp.find(t.component);
    if (it == comp.end())
      fail("thermal loop '" + loop.name + "': unknown component '" + t.component + "'");
    if (t.sign != 1.0 && t.sign != -1.0)
      fail("thermal loop '" + loop.name + "', component '" + t.component + "': sign " +
           num(t.sign) + " must be +1 or -1");
    const ThermalComponent& c = *it->second;
    const ExpansionCoefficient& k = *coef.at(c.coefficient);
    if (!group_length_mm.count(c.coefficient)) group_order.push_back(c.coefficient);
    group_length_mm[c.coefficient] += t.sign * c.length_mm;
    res.beta_um_per_K += t.sign * k.alpha_per_K * c.length_mm * 1000.0;
    // ∂δ/∂l_k = s_k α ΔT (µm per mm -> ·1000).
    length_terms.push_back({"l_" + c.name, "length of " + c.name + " (mm)",
                            standard_uncertainty(c.tolerance_mm, c.distribution),
                            t.sign * k.alpha_per_K * 1000.0 * model.temperature.delta_K});
  }
  std::vector<BudgetTerm> terms;
  // ∂δ/∂α_g = ΔT Σ_{k∈g} s_k l_k (mm·K -> µm: ·1000).
  for (const auto& g : group_order) {
    res.group_length_mm.emplace_back(g, group_length_mm[g]);
    const ExpansionCoefficient& k = *coef.at(g);
    terms.push_back({"alpha_" + g, "expansion coefficient " + g + " (1/K)",
                     standard_uncertainty(k.quoted_per_K, k.distribution),
                     group_length_mm[g] * 1000.0 * model.temperature.delta_K});
  }
  terms.insert(terms.end(), length_terms.begin(), length_terms.end());
  terms.push_back({"dT", "temperature change (K)",
                   standard_uncertainty(model.temperature.quoted_K, model.temperature.distribution),
                   res.beta_um_per_K});
  res.budget = combine_uncorrelated(terms, loop.symbol, "um");
  res.sigma_um = res.budget.combined;
  // σ_β from the same rows, without ΔT (Eqs. 34, 37, 40).
  double var_beta = 0;
  for (std::size_t i = 0; i + 1 < res.budget.rows.size(); ++i)
    var_beta += res.budget.rows[i].variance;
  const double dT = model.temperature.delta_K;
  res.sigma_beta_um_per_K = dT != 0 ? std::sqrt(var_beta) / std::abs(dT) : 0.0;
  return res;
}

BudgetEvaluation evaluate_budget(const BudgetSpec& spec) {
  if (!(std::isfinite(spec.round_sigma_um) && spec.round_sigma_um >= 0))
    fail("round_sigma_um = " + num(spec.round_sigma_um) + " must be finite and >= 0");
  BudgetEvaluation ev;
  std::map<std::string, double> loop_sigma;
  for (const auto& l : spec.loops) {
    if (loop_sigma.count(l.name)) fail("thermal loop '" + l.name + "' defined twice");
    ev.thermal.push_back(evaluate_thermal_loop(spec.thermal, l));
    loop_sigma[l.name] = ev.thermal.back().sigma_um;
  }
  std::vector<BudgetTerm> terms;
  for (const auto& t : spec.terms) {
    const bool has_value = t.quoted_um.has_value(), has_loop = !t.thermal_loop.empty();
    if (has_value == has_loop)
      fail("term '" + t.symbol + "': give exactly one of a value or a thermal loop");
    double u = 0;
    if (has_loop) {
      const auto it = loop_sigma.find(t.thermal_loop);
      if (it == loop_sigma.end())
        fail("term '" + t.symbol + "': unknown thermal loop '" + t.thermal_loop + "'");
      u = it->second;
    } else {
      if (!(std::isfinite(*t.quoted_um) && *t.quoted_um >= 0))
        fail("term '" + t.symbol + "': value " + num(*t.quoted_um) + " must be finite and >= 0");
      u = standard_uncertainty(*t.quoted_um, t.distribution);
    }
    if (spec.round_sigma_um > 0) u = std::round(u / spec.round_sigma_um) * spec.round_sigma_um;
    terms.push_back({t.symbol, t.description, u, t.sensitivity});
  }
  ev.budget = combine_uncorrelated(terms, spec.quantity, "um");
  return ev;
}

}  // namespace errsep::core

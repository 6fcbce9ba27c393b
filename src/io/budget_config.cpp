#include "errsep/io/budget_config.hpp"

#include <toml++/toml.h>

#include <fstream>
#include <optional>
#include <set>
#include <sstream>

#include "toml_table_reader.hpp"

namespace errsep::io {
namespace {

using detail::for_each_table;
using detail::line_of;
using Reader = detail::TomlTableReader;

double number(const Reader& r, const std::string& key, std::optional<double> fallback) {
  double v = fallback.value_or(0.0);
  r.get(key, v, !fallback.has_value());
  return v;
}

double non_negative(const Reader& r, const std::string& key,
                    std::optional<double> fallback = std::nullopt) {
  const double v = number(r, key, fallback);
  r.check(key, v >= 0, "must be >= 0 (got " + std::to_string(v) + ")");
  return v;
}

std::string string(const Reader& r, const std::string& key,
                   std::optional<std::string> fallback = std::nullopt) {
  std::string v = fallback.value_or(std::string());
  r.get(key, v, !fallback.has_value());
  return v;
}

core::Distribution distribution(const Reader& r, core::Distribution fallback) {
  if (!r.has("distribution")) return fallback;
  const std::string s = string(r, "distribution");
  for (const auto d : {core::Distribution::normal, core::Distribution::uniform})
    if (s == core::to_string(d)) return d;
  r.fail("distribution", "'" + s + "' is not a distribution (use \"normal\" or \"uniform\")");
}

/// [name.sub] tables keyed by a user-chosen name ([coefficients.steel], [components.spindle]).
template <typename F>
void for_each_named_table(const Reader& root, const std::string& key, F&& f) {
  if (!root.has(key)) root.fail("", "missing table [" + key + "]");
  const toml::table& t = *root.sub(key);
  for (const auto& [k, v] : t) {
    const std::string name(k.str());
    if (!v.is_table())
      throw ConfigError(root.file(), line_of(v), key + "." + name, "expected a table");
    f(name, Reader(root.file(), *v.as_table(), key + "." + name));
  }
}

core::BudgetSpec build(const toml::table& root_table, const std::string& file) {
  core::BudgetSpec spec;
  const Reader r(file, root_table, "");
  r.only({"title", "quantity", "round_sigma_um", "temperature", "coefficients", "components",
          "loop", "term"});
  spec.title = string(r, "title", "");
  spec.quantity = string(r, "quantity", "sigma_w");
  spec.round_sigma_um = non_negative(r, "round_sigma_um", 0.0);

  if (!r.has("temperature")) r.fail("", "missing table [temperature]");
  {
    const Reader tr(file, *r.sub("temperature"), "temperature");
    tr.only({"change_K", "uncertainty_K", "distribution"});
    spec.thermal.temperature.delta_K = number(tr, "change_K", std::nullopt);
    spec.thermal.temperature.quoted_K = non_negative(tr, "uncertainty_K");
    spec.thermal.temperature.distribution = distribution(tr, core::Distribution::uniform);
  }
  for_each_named_table(r, "coefficients", [&](const std::string& name, const Reader& cr) {
    cr.only({"alpha_per_K", "uncertainty_per_K", "distribution"});
    core::ExpansionCoefficient c;
    c.name = name;
    c.alpha_per_K = number(cr, "alpha_per_K", std::nullopt);
    c.quoted_per_K = non_negative(cr, "uncertainty_per_K");
    c.distribution = distribution(cr, core::Distribution::uniform);
    spec.thermal.coefficients.push_back(std::move(c));
  });
  for_each_named_table(r, "components", [&](const std::string& name, const Reader& cr) {
    cr.only({"length_mm", "tolerance_mm", "distribution", "coefficient"});
    core::ThermalComponent c;
    c.name = name;
    c.length_mm = non_negative(cr, "length_mm");
    c.tolerance_mm = non_negative(cr, "tolerance_mm");
    c.distribution = distribution(cr, core::Distribution::normal);
    c.coefficient = string(cr, "coefficient");
    bool known = false;
    for (const auto& e : spec.thermal.coefficients)
      known = known || e.name == c.coefficient;
    cr.check("coefficient", known,
             "unknown expansion coefficient '" + c.coefficient +
                 "' (define it under [coefficients." + c.coefficient + "])");
    spec.thermal.components.push_back(std::move(c));
  });
  std::set<std::string> loop_names;
  for_each_table(file, root_table, "loop", [&](const Reader& lr) {
    lr.only({"name", "symbol", "description", "components"});
    core::ThermalLoop loop;
    loop.name = string(lr, "name");
    lr.check("name", loop_names.insert(loop.name).second,
             "thermal loop '" + loop.name + "' defined twice");
    loop.symbol = string(lr, "symbol", "sigma_t" + loop.name);
    loop.description = string(lr, "description", "");
    lr.require("components");
    const toml::array* arr = lr.table().get("components")->as_array();
    lr.check("components", arr && !arr->empty(),
             "expected a non-empty list of \"+name\" / \"-name\"");
    for (const auto& e : *arr) {
      const auto s = e.value<std::string>();
      if (!s || s->size() < 2 || ((*s)[0] != '+' && (*s)[0] != '-'))
        lr.fail_at(e, "components", "each entry must be \"+name\" or \"-name\"");
      core::ThermalLoopTerm term{s->substr(1), (*s)[0] == '-' ? -1.0 : 1.0};
      bool known = false;
      for (const auto& c : spec.thermal.components)
        known = known || c.name == term.component;
      if (!known)
        lr.fail_at(e, "components",
                   "unknown component '" + term.component + "' (define it under [components." +
                       term.component + "])");
      loop.terms.push_back(std::move(term));
    }
    spec.loops.push_back(std::move(loop));
  });
  for_each_table(file, root_table, "term", [&](const Reader& tr) {
    tr.only({"symbol", "description", "sensitivity", "value_um", "thermal_loop", "distribution"});
    core::BudgetTermSpec t;
    t.symbol = string(tr, "symbol");
    t.description = string(tr, "description", "");
    t.sensitivity = number(tr, "sensitivity", 1.0);
    if (tr.has("value_um")) t.quoted_um = number(tr, "value_um", std::nullopt);
    t.thermal_loop = string(tr, "thermal_loop", "");
    t.distribution = distribution(tr, core::Distribution::normal);
    tr.check("value_um", !(t.quoted_um && !t.thermal_loop.empty()),
             "give either value_um or thermal_loop, not both");
    tr.check("", t.quoted_um || !t.thermal_loop.empty(), "needs value_um or thermal_loop");
    tr.check("value_um", !t.quoted_um || *t.quoted_um >= 0, "must be >= 0");
    tr.check("thermal_loop", t.thermal_loop.empty() || loop_names.count(t.thermal_loop),
             "unknown thermal loop '" + t.thermal_loop + "'");
    spec.terms.push_back(std::move(t));
  });
  if (spec.terms.empty()) r.fail("term", "at least one [[term]] is required");
  std::string why;
  if (!spec.thermal.is_valid(&why)) throw ConfigError(file, 0, "", why);
  return spec;
}

}  // namespace

core::BudgetSpec parse_budget_config(const std::string& toml_text, const std::string& name) {
  toml::table root;
  try {
    root = toml::parse(toml_text, name);
  } catch (const toml::parse_error& e) {
    throw ConfigError(name, static_cast<int>(e.source().begin.line), "",
                      std::string(e.description()));
  }
  return build(root, name);
}

core::BudgetSpec read_budget_config(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) throw ConfigError(file.string(), 0, "", "cannot open the budget config file");
  std::ostringstream ss;
  ss << in.rdbuf();
  return parse_budget_config(ss.str(), file.string());
}

}  // namespace errsep::io

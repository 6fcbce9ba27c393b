#include "errsep/io/budget_config.hpp"

#include <toml++/toml.h>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

namespace errsep::io {
namespace {

int line_of(const toml::node& n) {
  return static_cast<int>(n.source().begin.line);
}

/// Reads one TOML table, remembering which keys were used so unknown ones can be reported.
class TableReader {
 public:
  TableReader(const toml::table& t, std::string file, std::string prefix)
      : t_(t), file_(std::move(file)), prefix_(std::move(prefix)) {}

  [[noreturn]] void fail(const std::string& key, const std::string& problem,
                         const toml::node* n = nullptr) const {
    throw ConfigError(file_, n ? line_of(*n) : line_of(t_), full(key), problem);
  }
  std::string full(const std::string& key) const {
    return prefix_.empty() ? key : key.empty() ? prefix_ : prefix_ + "." + key;
  }
  const std::string& file() const { return file_; }

  const toml::node* get(const std::string& key) {
    used_.insert(key);
    return t_.get(key);
  }

  double number(const std::string& key, std::optional<double> fallback = std::nullopt) {
    const toml::node* n = get(key);
    if (!n) {
      if (fallback) return *fallback;
      fail(key, "missing (a number is required)");
    }
    if (!n->is_number()) fail(key, "expected a number", n);
    const double v = n->value<double>().value();
    if (!std::isfinite(v)) fail(key, "value is not finite", n);
    return v;
  }

  std::optional<double> optional_number(const std::string& key) {
    if (!t_.get(key)) {
      used_.insert(key);
      return std::nullopt;
    }
    return number(key);
  }

  double non_negative(const std::string& key, std::optional<double> fallback = std::nullopt) {
    const double v = number(key, fallback);
    if (v < 0) fail(key, "must be >= 0 (got " + std::to_string(v) + ")", t_.get(key));
    return v;
  }

  std::string string(const std::string& key, std::optional<std::string> fallback = std::nullopt) {
    const toml::node* n = get(key);
    if (!n) {
      if (fallback) return *fallback;
      fail(key, "missing (a string is required)");
    }
    if (!n->is_string()) fail(key, "expected a string", n);
    return n->value<std::string>().value();
  }

  core::Distribution distribution(const std::string& key, core::Distribution fallback) {
    const toml::node* n = t_.get(key);
    if (!n) {
      used_.insert(key);
      return fallback;
    }
    const std::string s = string(key);
    if (s == "normal") return core::Distribution::normal;
    if (s == "uniform") return core::Distribution::uniform;
    fail(key, "'" + s + "' is not a distribution (use \"normal\" or \"uniform\")", n);
  }

  void reject_unknown() const {
    for (const auto& [k, v] : t_)
      if (!used_.count(std::string(k.str())))
        throw ConfigError(file_, line_of(v), full(std::string(k.str())), "unknown key");
  }

 private:
  const toml::table& t_;
  std::string file_, prefix_;
  std::set<std::string> used_;
};

const toml::table& sub_table(TableReader& r, const std::string& key) {
  const toml::node* n = r.get(key);
  if (!n) r.fail(key, "missing table [" + r.full(key) + "]");
  if (!n->is_table()) r.fail(key, "expected a table", n);
  return *n->as_table();
}

const toml::array* array_of_tables(TableReader& r, const std::string& key) {
  const toml::node* n = r.get(key);
  if (!n) return nullptr;
  if (!n->is_array_of_tables()) r.fail(key, "expected [[" + key + "]] tables", n);
  return n->as_array();
}

core::BudgetSpec build(const toml::table& root, const std::string& file) {
  core::BudgetSpec spec;
  TableReader r(root, file, "");
  spec.title = r.string("title", std::string());
  spec.quantity = r.string("quantity", std::string("sigma_w"));
  spec.round_sigma_um = r.non_negative("round_sigma_um", 0.0);

  {
    const toml::table& t = sub_table(r, "temperature");
    TableReader tr(t, file, "temperature");
    spec.thermal.temperature.delta_K = tr.number("change_K");
    spec.thermal.temperature.quoted_K = tr.non_negative("uncertainty_K");
    spec.thermal.temperature.distribution =
        tr.distribution("distribution", core::Distribution::uniform);
    tr.reject_unknown();
  }
  {
    const toml::table& t = sub_table(r, "coefficients");
    for (const auto& [k, v] : t) {
      const std::string name(k.str());
      if (!v.is_table())
        throw ConfigError(file, line_of(v), "coefficients." + name, "expected a table");
      TableReader cr(*v.as_table(), file, "coefficients." + name);
      core::ExpansionCoefficient c;
      c.name = name;
      c.alpha_per_K = cr.number("alpha_per_K");
      c.quoted_per_K = cr.non_negative("uncertainty_per_K");
      c.distribution = cr.distribution("distribution", core::Distribution::uniform);
      cr.reject_unknown();
      spec.thermal.coefficients.push_back(std::move(c));
    }
  }
  {
    const toml::table& t = sub_table(r, "components");
    for (const auto& [k, v] : t) {
      const std::string name(k.str());
      if (!v.is_table())
        throw ConfigError(file, line_of(v), "components." + name, "expected a table");
      TableReader cr(*v.as_table(), file, "components." + name);
      core::ThermalComponent c;
      c.name = name;
      c.length_mm = cr.non_negative("length_mm");
      c.tolerance_mm = cr.non_negative("tolerance_mm");
      c.distribution = cr.distribution("distribution", core::Distribution::normal);
      c.coefficient = cr.string("coefficient");
      bool known = false;
      for (const auto& e : spec.thermal.coefficients)
        known = known || e.name == c.coefficient;
      if (!known)
        cr.fail("coefficient",
                "unknown expansion coefficient '" + c.coefficient +
                    "' (define it under [coefficients." + c.coefficient + "])",
                v.as_table()->get("coefficient"));
      cr.reject_unknown();
      spec.thermal.components.push_back(std::move(c));
    }
  }
  std::set<std::string> loop_names;
  if (const toml::array* loops = array_of_tables(r, "loop")) {
    for (std::size_t i = 0; i < loops->size(); ++i) {
      const toml::table& lt = *loops->get(i)->as_table();
      const std::string pre = "loop[" + std::to_string(i) + "]";
      TableReader lr(lt, file, pre);
      core::ThermalLoop loop;
      loop.name = lr.string("name");
      if (!loop_names.insert(loop.name).second)
        lr.fail("name", "thermal loop '" + loop.name + "' defined twice", lt.get("name"));
      loop.symbol = lr.string("symbol", "sigma_t" + loop.name);
      loop.description = lr.string("description", std::string());
      const toml::node* cn = lr.get("components");
      if (!cn) lr.fail("components", "missing (a list like [\"+A\", \"-B\"] is required)");
      if (!cn->is_array() || cn->as_array()->empty())
        lr.fail("components", "expected a non-empty list of \"+name\" / \"-name\"", cn);
      for (const auto& e : *cn->as_array()) {
        const auto s = e.value<std::string>();
        if (!s || s->size() < 2 || ((*s)[0] != '+' && (*s)[0] != '-'))
          lr.fail("components", "each entry must be \"+name\" or \"-name\"", &e);
        core::ThermalLoopTerm term{s->substr(1), (*s)[0] == '-' ? -1.0 : 1.0};
        bool known = false;
        for (const auto& c : spec.thermal.components)
          known = known || c.name == term.component;
        if (!known)
          lr.fail("components",
                  "unknown component '" + term.component + "' (define it under [components." +
                      term.component + "])",
                  &e);
        loop.terms.push_back(std::move(term));
      }
      lr.reject_unknown();
      spec.loops.push_back(std::move(loop));
    }
  }
  const toml::array* terms = array_of_tables(r, "term");
  if (!terms || terms->empty()) r.fail("term", "at least one [[term]] is required");
  for (std::size_t i = 0; i < terms->size(); ++i) {
    const toml::table& tt = *terms->get(i)->as_table();
    TableReader tr(tt, file, "term[" + std::to_string(i) + "]");
    core::BudgetTermSpec t;
    t.symbol = tr.string("symbol");
    t.description = tr.string("description", std::string());
    t.sensitivity = tr.number("sensitivity", 1.0);
    t.quoted_um = tr.optional_number("value_um");
    t.thermal_loop = tr.string("thermal_loop", std::string());
    t.distribution = tr.distribution("distribution", core::Distribution::normal);
    if (t.quoted_um && !t.thermal_loop.empty())
      tr.fail("value_um", "give either value_um or thermal_loop, not both", tt.get("value_um"));
    if (!t.quoted_um && t.thermal_loop.empty()) tr.fail("", "needs value_um or thermal_loop");
    if (t.quoted_um && *t.quoted_um < 0) tr.fail("value_um", "must be >= 0", tt.get("value_um"));
    if (!t.thermal_loop.empty() && !loop_names.count(t.thermal_loop))
      tr.fail("thermal_loop", "unknown thermal loop '" + t.thermal_loop + "'",
              tt.get("thermal_loop"));
    tr.reject_unknown();
    spec.terms.push_back(std::move(t));
  }
  r.reject_unknown();
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

#pragma once
// The one reader of errsep's TOML configs (the machine config, the uncertainty-budget config):
// typed values from one table, every problem a ConfigError "file:line: key: problem", unknown keys
// refused (a misspelt key must not fall back to a default silently).  Private to src/io.
#include <toml++/toml.h>

#include <cmath>
#include <initializer_list>
#include <set>
#include <string>
#include <vector>

#include "errsep/io/config_error.hpp"

namespace errsep::io::detail {

inline int line_of(const toml::node& n) {
  return static_cast<int>(n.source().begin.line);
}

/// Reads typed values from one table, reporting "file:line: key: problem".  `prefix` is the
/// table's path as the user would write it ("sensor[2]", "scan").
class TomlTableReader {
 public:
  TomlTableReader(const std::string& file, const toml::table& t, std::string prefix)
      : file_(file), t_(t), prefix_(std::move(prefix)) {}

  [[noreturn]] void fail(const std::string& key, const std::string& problem) const {
    const toml::node* n = key.empty() ? nullptr : t_.get(key);
    throw ConfigError(file_, n ? line_of(*n) : line_of(t_), full(key), problem);
  }
  /// The same, at the line of `at` (an element of an array, say).
  [[noreturn]] void fail_at(const toml::node& at, const std::string& key,
                            const std::string& problem) const {
    throw ConfigError(file_, line_of(at), full(key), problem);
  }
  std::string full(const std::string& key) const {
    if (key.empty()) return prefix_;
    return prefix_.empty() ? key : prefix_ + "." + key;
  }
  const toml::table& table() const { return t_; }
  const std::string& file() const { return file_; }

  /// Unknown keys are errors: a misspelt key must not silently fall back to a default.
  void only(std::initializer_list<const char*> allowed) const {
    std::set<std::string> ok(allowed.begin(), allowed.end());
    for (const auto& [k, v] : t_) {
      if (!ok.count(std::string(k.str()))) {
        std::string list;
        for (const char* a : allowed)
          list += (list.empty() ? "" : ", ") + std::string(a);
        throw ConfigError(file_, line_of(v), full(std::string(k.str())),
                          "unknown key (allowed here: " + list + ")");
      }
    }
  }
  bool has(const std::string& key) const { return t_.get(key) != nullptr; }
  void require(const std::string& key) const {
    if (!has(key)) fail("", "missing required key '" + key + "'");
  }

  void get(const std::string& key, std::string& out, bool required = false) const {
    const toml::node* n = t_.get(key);
    if (!n) {
      if (required) require(key);
      return;
    }
    if (!n->is_string()) fail(key, "expected a string");
    out = n->as_string()->get();
  }
  void get(const std::string& key, bool& out) const {
    const toml::node* n = t_.get(key);
    if (!n) return;
    if (!n->is_boolean()) fail(key, "expected true or false");
    out = n->as_boolean()->get();
  }
  void get(const std::string& key, double& out, bool required = false) const {
    const toml::node* n = t_.get(key);
    if (!n) {
      if (required) require(key);
      return;
    }
    if (n->is_floating_point())
      out = n->as_floating_point()->get();
    else if (n->is_integer())
      out = static_cast<double>(n->as_integer()->get());
    else
      fail(key, "expected a number");
    if (!std::isfinite(out)) fail(key, "must be finite");
  }
  template <typename Int>
  void get_int(const std::string& key, Int& out, long long lo, long long hi,
               bool required = false) const {
    const toml::node* n = t_.get(key);
    if (!n) {
      if (required) require(key);
      return;
    }
    if (!n->is_integer()) fail(key, "expected an integer");
    const long long v = n->as_integer()->get();
    if (v < lo || v > hi)
      fail(key, std::to_string(v) + " is out of range " + std::to_string(lo) + ".." +
                    std::to_string(hi));
    out = static_cast<Int>(v);
  }
  void check(const std::string& key, bool cond, const std::string& problem) const {
    if (!cond) fail(key, problem);
  }
  const toml::table* sub(const std::string& key) const {
    const toml::node* n = t_.get(key);
    if (!n) return nullptr;
    if (!n->is_table()) fail(key, "expected a table, e.g. " + key + " = { ... }");
    return n->as_table();
  }

 private:
  const std::string& file_;
  const toml::table& t_;
  std::string prefix_;
};

inline std::vector<std::string> read_string_list(const TomlTableReader& r, const std::string& key) {
  std::vector<std::string> out;
  const toml::node* n = r.table().get(key);
  if (!n) return out;
  const toml::array* arr = n->as_array();
  if (!arr) r.fail(key, "expected an array of names, e.g. [\"sensor1\"]");
  for (const auto& e : *arr) {
    if (!e.is_string()) r.fail(key, "every element must be a string");
    out.push_back(e.as_string()->get());
  }
  return out;
}

/// Iterates an array of tables ([[bus]]), giving each a TomlTableReader "bus[i]".
template <typename F>
void for_each_table(const std::string& file, const toml::table& root, const std::string& key,
                    F&& f) {
  const toml::node* n = root.get(key);
  if (!n) return;
  const toml::array* arr = n->as_array();
  if (!arr || !arr->is_array_of_tables())
    throw ConfigError(file, line_of(*n), key, "expected [[" + key + "]] tables");
  for (std::size_t i = 0; i < arr->size(); ++i)
    f(TomlTableReader(file, *arr->get(i)->as_table(), key + "[" + std::to_string(i) + "]"));
}

}  // namespace errsep::io::detail

#include "errsep/io/mqtt_messages.hpp"

#include "errsep/core/four_sensor_evaluation.hpp"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <ctime>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "errsep/core/iso230.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/results_store.hpp"
#include "errsep/io/utc_time.hpp"

namespace errsep::io {
namespace {

using nlohmann::json;

std::optional<double> number(const CsvTable& t, const char* key) {
  const auto v = t.meta(key);
  if (!v) return std::nullopt;
  try {
    std::size_t used = 0;
    const double d = std::stod(*v, &used);
    if (used != v->size() || !std::isfinite(d)) return std::nullopt;
    return d;
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

std::string text(const CsvTable& t, const char* key) {
  return t.meta(key).value_or("");
}

json opt(const std::optional<double>& v) {
  return v ? json(*v) : json(nullptr);
}

}  // namespace

ScanSummary summarize_stored_scan(const std::filesystem::path& store_dir, std::string_view stem,
                                  const std::string& machine) {
  ScanSummary s;
  s.machine = machine;
  s.scan_id = std::string(stem);
  std::optional<std::filesystem::path> result, raw, incomplete;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(store_dir, ec)) {
    const auto f = parse_store_name(e.path());
    if (!f || f->stem != stem) continue;
    s.scan_number = f->scan_id;
    s.files.push_back(e.path().filename().string());
    if (f->kind == "result") result = e.path();
    if (f->kind == "raw") raw = e.path();
    if (f->kind == "raw-incomplete") incomplete = e.path();
  }
  std::sort(s.files.begin(), s.files.end());
  const auto source = result ? result : raw ? raw : incomplete;
  if (!source)
    throw std::runtime_error("scan summary: no file of scan " + std::string(stem) + " in " +
                             store_dir.string());
  CsvReadOptions ro;
  ro.allow_non_finite = true;  // a raw-incomplete file has NaN where nothing was measured
  ro.min_rows = 0;
  const CsvTable t = read_csv(*source, ro);
  s.started_utc = text(t, "started_utc");
  s.ended_utc = text(t, "ended_utc");
  s.trigger = text(t, "trigger");
  s.outcome = text(t, "outcome");
  s.outcome_reason = text(t, "outcome_reason");
  s.points_measured = text(t, "points_measured");
  if (result) {
    s.straightness_minimum_zone_um = number(t, "straightness_minimum_zone_um");
    s.straightness_minimum_zone_U_um = number(t, "straightness_minimum_zone_U_um");
    s.straightness_least_squares_um = number(t, "straightness_least_squares_um");
    s.straightness_least_squares_U_um = number(t, "straightness_least_squares_U_um");
    s.lambda = number(t, "lambda");
    s.sigma_hat_um = number(t, "sigma_hat_um");
    s.solver = text(t, "solver");
  } else if (raw && s.outcome == "complete") {
    s.outcome_reason = "separation failed: raw data kept, no result";
  }
  return s;
}

void add_separation(ScanSummary& s, const core::FourSensorResult& r) {
  // The figures the result files state (U from the separation's covariance, the noise's bias of
  // max - min removed), so the plant sees what the local report says.
  const auto mz = core::four_sensor_straightness(r, core::ReferenceLine::minimum_zone);
  const auto ls = core::four_sensor_straightness(r, core::ReferenceLine::least_squares);
  const bool have_u = r.covariance || r.u_S_um.size() == r.x_mm.size();
  auto finite = [](double v) { return std::isfinite(v) ? std::optional<double>(v) : std::nullopt; };
  s.straightness_minimum_zone_um = finite(mz.straightness_um);
  s.straightness_minimum_zone_U_um = have_u ? finite(mz.expanded_um) : std::nullopt;
  s.straightness_least_squares_um = finite(ls.straightness_um);
  s.straightness_least_squares_U_um = have_u ? finite(ls.expanded_um) : std::nullopt;
  s.lambda = finite(r.lambda);
  s.sigma_hat_um = finite(r.sigma_um);
  s.solver = r.brief_report();
}

std::string to_json(const ScanSummary& s) {
  json j = {{"type", "scan"},
            {"schema_version", kMqttSchemaVersion},
            {"machine", s.machine},
            {"scan_id", s.scan_id},
            {"scan_number", s.scan_number},
            {"started_utc", s.started_utc},
            {"ended_utc", s.ended_utc},
            {"trigger", s.trigger},
            {"method", s.method},
            {"outcome", s.outcome},
            {"outcome_reason", s.outcome_reason},
            {"points_measured", s.points_measured},
            {"files", s.files}};
  if (s.straightness_minimum_zone_um)
    j["straightness"] = {{"minimum_zone_um", opt(s.straightness_minimum_zone_um)},
                         {"minimum_zone_U_um", opt(s.straightness_minimum_zone_U_um)},
                         {"least_squares_um", opt(s.straightness_least_squares_um)},
                         {"least_squares_U_um", opt(s.straightness_least_squares_U_um)},
                         {"coverage_factor", 2}};
  else
    j["straightness"] = nullptr;
  j["separation"] = s.straightness_minimum_zone_um ? json{{"lambda", opt(s.lambda)},
                                                          {"sigma_hat_um", opt(s.sigma_hat_um)},
                                                          {"solver", s.solver}}
                                                   : json(nullptr);
  if (s.refine)
    j["refine"] = {{"model_complete", s.refine->model_complete},
                   {"verdict", s.refine->verdict},
                   {"model", s.refine->model},
                   {"steps", s.refine->steps}};
  else
    j["refine"] = nullptr;
  return j.dump();
}

std::vector<Alarm> alarms_for(const ScanSummary& s, double tolerance_um) {
  std::vector<Alarm> out;
  auto base = [&](const char* kind, std::string msg) {
    Alarm a;
    a.machine = s.machine;
    a.scan_id = s.scan_id;
    a.kind = kind;
    a.message = std::move(msg);
    return a;
  };
  if (s.outcome == "device_fault")
    out.push_back(base("device_fault", "scan " + s.scan_id + ": " + s.outcome_reason));
  if (s.outcome == "write_failed")
    out.push_back(
        base("write_failed", "scan " + s.scan_id + ": results not written: " + s.outcome_reason));
  if (tolerance_um > 0 && s.straightness_minimum_zone_um &&
      *s.straightness_minimum_zone_um > tolerance_um) {
    const double U = s.straightness_minimum_zone_U_um.value_or(0.0);
    Alarm a = base("straightness_tolerance",
                   "scan " + s.scan_id + ": straightness (minimum zone) " +
                       std::to_string(*s.straightness_minimum_zone_um) + " um > tolerance " +
                       std::to_string(tolerance_um) + " um");
    a.value_um = s.straightness_minimum_zone_um;
    a.U_um = U;
    a.tolerance_um = tolerance_um;
    a.proven = *s.straightness_minimum_zone_um - U > tolerance_um;
    out.push_back(std::move(a));
  }
  return out;
}

std::string to_json(const Alarm& a) {
  json j = {{"type", "alarm"},          {"schema_version", kMqttSchemaVersion},
            {"machine", a.machine},     {"scan_id", a.scan_id},
            {"kind", a.kind},           {"message", a.message},
            {"time_utc", utc_now_iso()}};
  if (a.value_um) j["value_um"] = *a.value_um;
  if (a.U_um) j["U_um"] = *a.U_um;
  if (a.tolerance_um) j["tolerance_um"] = *a.tolerance_um;
  if (a.proven) j["proven"] = *a.proven;
  return j.dump();
}

std::string to_json(const StatusMessage& s) {
  json j = {{"type", "status"},
            {"schema_version", kMqttSchemaVersion},
            {"machine", s.machine},
            {"online", s.online},
            {"state", s.state},
            {"message", s.message},
            {"last_scan_id", s.last_scan_id},
            {"queued", s.queued},
            {"time_utc", s.time_utc.empty() ? utc_now_iso() : s.time_utc}};
  return j.dump();
}

std::optional<ScanCommand> parse_scan_command(std::string_view payload, std::string* why) {
  auto bad = [&](const std::string& m) -> std::optional<ScanCommand> {
    if (why) *why = m;
    return std::nullopt;
  };
  if (payload.size() > 1024) return bad("payload longer than 1024 bytes");
  const json j = json::parse(payload.begin(), payload.end(), nullptr, false);
  if (j.is_discarded()) return bad("not JSON (expected {\"request_id\": \"...\"})");
  if (!j.is_object()) return bad("not a JSON object (expected {\"request_id\": \"...\"})");
  for (const auto& [k, v] : j.items())
    if (k != "request_id") return bad("unknown key '" + k + "' (allowed: request_id)");
  const auto it = j.find("request_id");
  if (it == j.end()) return bad("missing key 'request_id'");
  if (!it->is_string()) return bad("request_id must be a string");
  ScanCommand c;
  c.request_id = it->get<std::string>();
  if (c.request_id.empty() || c.request_id.size() > 64)
    return bad("request_id must have 1 to 64 characters");
  for (unsigned char ch : c.request_id)
    if (ch < 0x20 || ch == 0x7f) return bad("request_id has a control character");
  return c;
}

std::string to_json(const CommandReply& r) {
  json j = {
      {"type", "command_reply"},    {"schema_version", kMqttSchemaVersion},
      {"machine", r.machine},       {"command", "scan"},
      {"request_id", r.request_id}, {"accepted", r.accepted},
      {"reason", r.reason},         {"time_utc", r.time_utc.empty() ? utc_now_iso() : r.time_utc}};
  return j.dump();
}

}  // namespace errsep::io

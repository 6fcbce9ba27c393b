#pragma once
// The JSON payloads of errsep's MQTT topic tree (one machine = <prefix>/<machine>):
//
//   status            retained; {"type":"status","online":true,...} on connect (birth) and on
//                     every change of the daemon's state, {"online":false,"state":"offline"} as
//                     the last will (the broker sends it when the connection dies uncleanly)
//   scan/<scan id>    one per scan, after its files are written locally: time, method,
//                     outcome, ISO 230-1 straightness with U (k = 2), λ, σ̂, refine verdict and
//                     steps (when run), file names
//   alarm             a tolerance exceeded, a device fault, results not written
//   cmd/scan          (in) a request for a scan: {"request_id":"..."}; only with [mqtt] commands
//   cmd/scan/reply    accepted or refused, with the reason, for every cmd/scan payload
//
// Every payload validates against schema/mqtt-messages.schema.json (tests check each message
// they receive).  Every scan and alarm message carries the scan id ("<UTC start>_scan<number>"
// of the results store, unique per machine), so a subscriber drops duplicates by (machine,
// scan_id): store and forward delivers at least once.
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "errsep/core/four_sensor.hpp"
#include "errsep/io/utc_time.hpp"  // utc_iso, utc_now_iso

namespace errsep::io {

inline constexpr int kMqttSchemaVersion = 1;

struct ScanSummary {
  std::string machine;
  std::string scan_id;  ///< "<UTC start>_scan<number>" (store stem), unique per machine
  std::uint64_t scan_number = 0;
  std::string started_utc, ended_utc;
  std::string trigger;  ///< modbus, gpio, schedule, command, mqtt, manual
  std::string method = "four_sensor";
  std::string outcome;  ///< complete, aborted, device_fault, stopped, write_failed
  std::string outcome_reason;
  std::string points_measured;  ///< "done/total"
  // ISO 230-1 straightness of S(x), expanded uncertainty U (k = 2); absent when not separated.
  std::optional<double> straightness_minimum_zone_um, straightness_minimum_zone_U_um;
  std::optional<double> straightness_least_squares_um, straightness_least_squares_U_um;
  std::optional<double> lambda;        ///< Tikhonov λ of the separation (0 = none)
  std::optional<double> sigma_hat_um;  ///< σ̂ from the redundant equations
  std::string solver;                  ///< the separation's one-line report
  struct Refine {
    bool model_complete = false;
    std::string verdict;             ///< one line (RefineResult::brief_report)
    std::string model;               ///< e.g. "zhao2019-eq1+gain"
    std::vector<std::string> steps;  ///< effect added at each step after the base
  };
  std::optional<Refine> refine;    ///< absent when the refine step did not run
  std::vector<std::string> files;  ///< file names written locally
};

/// The summary of a scan of the results store (dir/<stem>.*.csv): its result file's metadata, or
/// its raw / raw-incomplete file's when there is no result.  Throws std::runtime_error naming the
/// file when none of them can be read.
ScanSummary summarize_stored_scan(const std::filesystem::path& store_dir, std::string_view stem,
                                  const std::string& machine);

std::string to_json(const ScanSummary& s);

/// The summary of a scan that errsep-scan separated (no results store): ISO 230-1 straightness
/// of r.S_um with U (k = 2, bound over any correlation of u_S, as the daemon's result files),
/// λ and σ̂ of the separation.  Identity, times, trigger and files are the caller's.
void add_separation(ScanSummary& s, const core::FourSensorResult& r);

struct Alarm {
  std::string machine, scan_id;
  std::string kind;  ///< straightness_tolerance, device_fault, write_failed
  std::string message;
  std::optional<double> value_um, U_um, tolerance_um;
  /// straightness_tolerance: true when value − U > tolerance (exceeded beyond doubt, ISO
  /// 14253-1); false when only the measured value exceeds it.
  std::optional<bool> proven;
};

/// Alarms a scan raises: its minimum-zone straightness above `tolerance_um` (> 0), a device
/// fault, results that could not be written.
std::vector<Alarm> alarms_for(const ScanSummary& s, double tolerance_um);
std::string to_json(const Alarm& a);

struct StatusMessage {
  std::string machine;
  bool online = true;
  std::string state;  ///< the daemon's state (idle, scanning, fault, ...) or "offline"
  std::string message;
  std::string last_scan_id;
  std::uint64_t queued = 0;  ///< messages waiting in the store-and-forward queue
  std::string time_utc;
};
std::string to_json(const StatusMessage& s);

/// A cmd/scan payload: {"request_id": "<1-64 printable characters>"} and nothing else.
struct ScanCommand {
  std::string request_id;
};
/// Parses a cmd/scan payload; nullopt (and the reason in `why`) when malformed.
std::optional<ScanCommand> parse_scan_command(std::string_view payload, std::string* why);

struct CommandReply {
  std::string machine;
  std::string request_id;  ///< empty when the request had none (malformed)
  bool accepted = false;
  std::string reason;  ///< why refused ("" when accepted)
  std::string time_utc;
};
std::string to_json(const CommandReply& r);

}  // namespace errsep::io

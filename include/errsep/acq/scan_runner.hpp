#pragma once
// The scan runner: moves the stages, samples the sensors through the sampling threads and rings,
// averages K readings per point, and records what it saw as a raw scan.
//
//  - Four-sensor scan (Zhao 2019, section 2): four configurations, either four sensors read at
//    once at each slide position, or one sensor moved by its sensor stage to the four offsets
//    0, D2, D2+D3, D2+D3+D4 with a full slide pass per configuration (the paper's set-up).
//  - Displacement-method scan (Haramiishi 2024, Eqs. 1-3): workpiece and reference-piece sensors
//    read over the slide travel; the reference piece is displaced by d; a second pass.
//
// At each point: move, wait in position, settle, then average K ok readings taken after the
// settle (samples from moves are discarded).  A failed point is re-read (retries, counted); a
// sensor that keeps failing, a stage fault or a move timeout ends the scan with a message naming
// the device and the point; Ctrl-C (the abort flag) ends it at once.  In every one of these cases
// the stages are stopped, the data measured so far is kept (cells not reached are nan) and the
// result is marked incomplete: nothing partial is presented as complete.
//
// Not real-time safe (the scan thread moves stages and waits); the real-time part is the
// Sampler it starts, one per bus.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "errsep/acq/displacement_sensor.hpp"
#include "errsep/acq/sampler.hpp"
#include "errsep/acq/stage.hpp"
#include "errsep/core/displacement_scan_order.hpp"
#include "errsep/core/four_sensor_config.hpp"
#include "errsep/core/machine_axes.hpp"
#include "errsep/io/machine_config.hpp"
#include "errsep/io/raw_scan_csv.hpp"

namespace errsep::acq {

enum class ScanKind { four_sensor, displacement };
const char* to_string(ScanKind k) noexcept;

struct ScanOptions {
  ScanKind kind = ScanKind::four_sensor;
  core::FourSensorConfig geometry;  ///< Δx, s2, s3, s4, N (four-sensor)
  double slide_start_mm = 0.0;      ///< slide position of x_0; raw x_mm is relative to it
  /// Machine axes (core/machine_axes.hpp): the slide goes to slide_start_mm +
  /// axes.scan_direction * x; all of it is recorded in the raw file's metadata.
  core::MachineAxes axes;
  double sensor_stage_origin_mm = 0.0;  ///< sensor-stage position of configuration 1
  int averages = 100;                   ///< K ok readings averaged per point
  int settle_ms = 50;                   ///< wait after in-position before averaging
  /// The order of the traverses (core/scan_sequence.hpp), one sensor on the sensor stage only.
  /// Other than single, the raw record holds every traverse (io::RawSequence: configuration,
  /// direction, start time, each reading's time); a backward traverse reads x_{P-1} first.
  core::ScanSequenceKind plan = core::ScanSequenceKind::single;
  // displacement method
  double d_mm = 5.0;                 ///< displacement of the reference piece (also the spacing)
  int displacement_points = 25;      ///< slide positions per pass, x_k = k·d
  double reference_origin_mm = 0.0;  ///< reference-piece position of the first pass
  /// The order pass 2 reads the points in (core/displacement_scan_order.hpp), recorded in the raw
  /// file; backward reads x_{K-1} first.
  core::DisplacementScanOrder scan2_order = core::DisplacementScanOrder::forward;
  // timing and robustness
  int move_timeout_ms = 30000;        ///< per move, wait-in-position included
  int max_errors_per_point = 20;      ///< failed readings in one window before it is re-read
  int point_retries = 2;              ///< re-reads of a point before the scan fails
  SamplerOptions sampler;             ///< rate, real-time set-up (per bus sampler)
  std::size_t ring_capacity = 65536;  ///< samples per bus ring
  /// The measuring range of each column's sensor, written into the raw file's metadata so that a
  /// reader can refuse a reading no sensor can give (io/plausibility.hpp); sensor_range_metadata.
  std::vector<std::pair<std::string, std::string>> range_metadata;

  /// Time allowed to collect one window of K readings: 4·K periods + 1 s, periods of `rate_hz`
  /// (the slowest bus of the scan; 0 = sampler.rate_hz).
  std::chrono::milliseconds window_timeout(double rate_hz = 0.0) const;
  bool is_valid(std::string* why = nullptr) const;
};

/// The raw file's metadata lines of the measuring range of each column's sensor, from the machine
/// config's [[sensor]] range_min_um / range_max_um: m1..m4 for a four-sensor scan (one sensor on
/// the sensor stage: its range for all four), s1 (workpiece) and s2 (reference piece) for a
/// displacement scan (io/plausibility.hpp).  Sensors the config does not name are left out.
std::vector<std::pair<std::string, std::string>> sensor_range_metadata(const io::MachineConfig& cfg,
                                                                       ScanKind kind);

/// The scan options a machine config describes (method "both" is the caller's loop; this takes
/// `kind`).  Throws std::invalid_argument when the config's [scan] cannot give that kind.
ScanOptions scan_options_from_config(const io::MachineConfig& cfg, ScanKind kind);

/// The devices a scan uses.  Pointers are not owned and must be configured.
struct ScanDevices {
  Stage* slide = nullptr;            ///< required
  Stage* sensor_stage = nullptr;     ///< required for a four-sensor scan with one sensor
  Stage* reference_stage = nullptr;  ///< required for a displacement scan
  /// Four-sensor: 1 sensor (moved by the sensor stage) or 4 (configurations 1..4).
  /// Displacement: {workpiece sensor, reference-piece sensor}.
  std::vector<DisplacementSensor*> sensors;
  /// Bus index of each sensor: sensors on one bus share one sampling thread (a bus context is
  /// used by one thread).  Empty = all on one bus.
  std::vector<std::size_t> sensor_bus;
  /// Sampling rate of each bus's thread, by bus index ([[bus]] sample_rate_hz); a bus without an
  /// entry, or 0, samples at ScanOptions::sampler.rate_hz.
  std::vector<double> bus_rate_hz;
};

struct ScanProgress {
  std::string phase;  ///< "configuration 2/4", "scan 1/2", ...
  int point = 0;      ///< points done so far (all phases)
  int points_total = 0;
  double x_mm = 0.0;              ///< slide position of the point just measured (relative to x_0)
  std::vector<double> values_um;  ///< its averages, one per sensor measured
};

struct ScanHooks {
  /// Called on the scan thread after each point (may print; must not throw).
  std::function<void(const ScanProgress&)> progress;
  /// Set to true (from a signal handler, say) to stop the scan: stages stopped, data kept,
  /// result incomplete.
  const std::atomic<bool>* abort = nullptr;
  /// Called on the scan thread for each cell of the raw record as soon as it is measured, so a
  /// caller can keep what was measured even if the scan never returns (the daemon's checkpoints).
  /// `column`: four-sensor, the configuration 0..3 (m1..m4); displacement, 0 s1 scan 1, 1 s2
  /// scan 1, 2 s1 scan 2, 3 s2 scan 2.  `n`: the point's index; `t_s`: its mean time since the
  /// scan started.  Must not throw.
  std::function<void(std::size_t column, std::size_t n, double value_um, double t_s)> cell;
  /// Called on the scan thread at least every ~100 ms while it moves or settles (and after each
  /// point): proof of life for a watchdog.  Must not throw.
  std::function<void()> heartbeat;
};

enum class ScanRunOutcome { complete, aborted, failed };
const char* to_string(ScanRunOutcome o) noexcept;

/// Counts reported in the raw file's metadata.
struct ScanCounts {
  std::uint64_t samples = 0;           ///< samples pushed into the rings by the sampling threads
  std::uint64_t samples_consumed = 0;  ///< samples drained from the rings (== samples: none lost)
  std::uint64_t samples_averaged = 0;  ///< ok readings that went into the recorded averages
  std::uint64_t periods = 0, missed_periods = 0, overruns = 0;
  std::array<std::uint64_t, kIoStatusCount> reads_by_status{};
  std::uint64_t read_errors = 0;    ///< reads whose status was not ok
  std::uint64_t point_retries = 0;  ///< points re-read after failed readings
  /// Stage commands left unanswered or polls that found the link down, each waited for (the bus
  /// supervisor reconnects) and the target commanded again, within the move's deadline.
  std::uint64_t stage_link_waits = 0;
  int points_done = 0, points_total = 0;
};

struct ScanResult {
  ScanKind kind = ScanKind::four_sensor;
  ScanRunOutcome outcome = ScanRunOutcome::failed;
  std::string stop_reason;  ///< empty when complete; otherwise what stopped it, with the device
  std::optional<io::RawFourSensorScan> four_sensor;     ///< set for a four-sensor scan
  std::optional<io::RawDisplacementScan> displacement;  ///< set for a displacement scan
  std::vector<SamplerStats> samplers;                   ///< one per bus
  ScanCounts counts;
  std::string started_utc, finished_utc;
  double duration_s = 0.0;

  bool complete() const { return outcome == ScanRunOutcome::complete; }
  /// One line: outcome, points, samples, missed periods, overruns, errors, retries, jitter.
  std::string brief_report() const;
};

/// Runs a scan.  Throws std::invalid_argument for invalid options or devices that do not fit
/// the kind of scan (before anything moves).  Device problems during the scan do not throw:
/// they end it with outcome failed and a stop_reason.  Not real-time safe.
ScanResult run_scan(const ScanDevices& devices, const ScanOptions& opts,
                    const ScanHooks& hooks = {});

}  // namespace errsep::acq

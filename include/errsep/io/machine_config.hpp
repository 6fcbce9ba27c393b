#pragma once
// The machine config: buses, sensors, stages, optional GPIO, the sampler, the scan and the device
// simulator, read from a TOML file (config/simulator.toml is the embedded default,
// config/machine-example.toml a commented example for a real machine).
//
// Every error is a ConfigError whose message is "file:line: key: what is wrong" (for a missing
// key, the line of the table that lacks it), so a user can fix the file without reading code.
// Unknown keys are errors (a misspelt key must not fall back to a default silently).  Cross
// references (a sensor's bus, the scan's sensors and stages and their roles) are checked when
// loading.
#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "errsep/core/compensation.hpp"
#include "errsep/core/displacement_scan_order.hpp"
#include "errsep/core/four_sensor.hpp"
#include "errsep/core/four_sensor_config.hpp"
#include "errsep/core/machine_axes.hpp"
#include "errsep/core/scan_sequence.hpp"
#include "errsep/io/cnc/compensation_export.hpp"
#include "errsep/io/config_error.hpp"
#include "errsep/io/register_spec.hpp"

namespace errsep::io {

enum class BusKind { tcp, rtu };
enum class Parity { none, even, odd };

/// One physical bus = one libmodbus context ([[bus]]).
struct BusConfig {
  std::string name;
  BusKind kind = BusKind::tcp;
  // tcp
  std::string host = "127.0.0.1";
  int port = 502;  ///< 0 only for the embedded simulator: replaced by its actual port at start
  // rtu
  std::string device;  ///< serial device, e.g. /dev/ttyUSB0
  int baud = 115200;
  Parity parity = Parity::none;
  int data_bits = 8;
  int stop_bits = 1;
  // both
  int response_timeout_ms = 50;  ///< per request; keep below the sample period
  int retries = 1;               ///< extra attempts after a timeout (0 = none)
  double sample_rate_hz = 0.0;   ///< sampling rate of this bus's thread; 0 = sampler.rate_hz
};

/// A displacement sensor ([[sensor]]): one register, decoded to µm.
struct SensorConfig {
  std::string name;
  std::string bus;                ///< name of a [[bus]]
  RegisterSpec reg;               ///< value register; scale/offset give µm
  double range_min_um = -1000.0;  ///< measuring range: readings outside are out_of_range
  double range_max_um = 1000.0;
};

enum class StageRole { slide, sensor_stage, reference_piece };

/// A positioning stage ([[stage]]).  Positions in mm (register scale/offset give mm).
struct StageConfig {
  std::string name;
  StageRole role = StageRole::slide;
  std::string bus;
  RegisterSpec target_position;            ///< holding register(s), written by move_to
  RegisterSpec actual_position;            ///< input or holding register(s)
  RegisterSpec status;                     ///< a 16-bit register holding the bits below
  int in_position_bit = 0;                 ///< bit of `status` set when in position and settled
  int fault_bit = 1;                       ///< bit of `status` set on a drive fault
  RegisterSpec stop_coil;                  ///< coil; writing 1 stops motion
  std::optional<RegisterSpec> fault_code;  ///< optional fault word register
  std::optional<RegisterSpec> speed;       ///< optional holding register, mm/s
  double speed_mm_s = 0.0;                 ///< written to `speed` at configure when > 0
  double position_tolerance_mm = 0.001;    ///< |actual − target| accepted as "there"
  int move_timeout_ms = 30000;             ///< wait_in_position timeout used by the scan
};

/// Digital I/O on a gpiochip ([gpio], optional).  Lines are offsets on the chip; −1 = unused.
struct GpioConfig {
  std::string chip = "gpiochip0";
  int start_line = -1;    ///< input: start button (rising edge starts a scan)
  int trigger_line = -1;  ///< input: external trigger / encoder index
  int output_line = -1;   ///< output: e.g. "scan running" lamp
};

/// The sampling threads ([sampler]).
struct SamplerConfig {
  double rate_hz = 1000.0;
  bool realtime = false;   ///< try SCHED_FIFO + mlockall (warning, not failure, when refused)
  int cpu_affinity = -1;   ///< CPU to pin the sampling threads to; −1 = none
  int fifo_priority = 80;  ///< SCHED_FIFO priority when realtime
  std::size_t ring_capacity = 65536;  ///< samples per bus ring
};

enum class ScanMethod { four_sensor, displacement, both };

/// The scan ([scan]).
struct ScanConfig {
  ScanMethod method = ScanMethod::four_sensor;
  core::FourSensorConfig geometry;  ///< dx_mm, s2, s3, s4, N (Zhao 2019)
  /// true: one sensor on the sensor stage moved to the four configurations (Zhao 2019's set-up);
  /// false: four sensors, fixed at the four configuration offsets.
  bool single_sensor = true;
  /// Sensors in configuration order: one name when single_sensor, four otherwise.
  std::vector<std::string> sensors;
  std::string slide_stage;              ///< role slide
  std::string sensor_stage;             ///< role sensor_stage (single_sensor only)
  double slide_start_mm = 0.0;          ///< slide position of x_0
  double sensor_stage_origin_mm = 0.0;  ///< sensor-stage position of configuration 1
  int averages = 100;  ///< K readings averaged per point (Zhao 2019's experiment used 100)
  int settle_ms = 50;  ///< wait after in-position before averaging
  /// The order of the traverses (core/scan_sequence.hpp; "plan" = single, closing, reversed,
  /// interleaved): a plan other than single measures configurations again so that drift and a
  /// non-repeating traverse show (issue 16 item 2); single_sensor set-ups only.
  core::ScanSequenceKind plan = core::ScanSequenceKind::single;
  // displacement method (Haramiishi 2024, section 2.1)
  double d_mm = 5.0;            ///< displacement of the reference piece between the scans
  int displacement_points = 0;  ///< points per scan, spaced d_mm (0 = geometry.N)
  /// The order scan 2 reads its points in (core/displacement_scan_order.hpp): backward makes a
  /// linear drift of the workpiece sensor identifiable (issue 16 item 4).
  core::DisplacementScanOrder scan2_order = core::DisplacementScanOrder::forward;
  std::string workpiece_sensor;  ///< reads w(x) + m(x)
  std::string reference_sensor;  ///< reads r(x) + m(x), then r(x + d) + m(x)
  std::string reference_stage;   ///< role reference_piece: displaces the reference piece
  std::filesystem::path output_dir = "scans";  ///< relative to the current directory
};

/// The refine step after a four-sensor scan ([refine], errsep-refine; core/refine.hpp).
struct RefineConfig {
  bool enabled = false;  ///< true: errsep-scan runs it as with --refine
  double alpha = 0.01;   ///< family-wise significance of one step (RefineOptions::alpha)
};

/// The four-sensor separation's settings ([separation], optional): one vocabulary for
/// errsep-scan, errsep-separate, errsep-refine and the daemon (their command-line options override
/// it).  Names as core's to_string of each enum: gauge = "reference" | "sensor_stage" |
/// "paper_eq12", lambda_rule = "reml" | "gcv" | "lcurve" | "discrepancy" | "fixed" |
/// "least_squares".
struct SeparationConfig {
  core::CurvatureGauge gauge = core::CurvatureGauge::reference_without_curvature;
  /// Unset: the gauge's own (core::options_for_gauge: REML for the exact gauge, the paper's
  /// L-curve for the others).
  std::optional<core::LambdaRule> lambda_rule;
  /// λ range of the L-curve grid (lambda_rule lcurve and discrepancy); 0 = automatic (the bound
  /// of σ_max(A) and 8 decades below it).  REML and GCV search a range relative to σ_max.
  double lambda_min = 0, lambda_max = 0;
  double fixed_lambda = 0;  ///< lambda_rule fixed
  int threads = 1;          ///< threads of the λ search (the result does not depend on them)
  bool is_valid(std::string* why) const;
  /// The separation's options: core::options_for_gauge(gauge) with the settings above.
  core::FourSensorOptions options() const;
};

/// What the customer's report states beyond the data ([report], optional; io/scan_report.hpp).
/// Empty / unset: "not stated" in the report.
struct ReportConfig {
  std::string machine;                  ///< e.g. "DMU 50 #3, hall 2" (default: [mqtt] machine)
  std::string operator_name;            ///< key `operator`
  std::string instrument;               ///< e.g. "four-sensor rig, probe GT2-P12"
  std::optional<double> temperature_c;  ///< environment temperature during scans, °C
  /// Straightness tolerance (minimum zone of S): the report gives a pass/fail verdict (default:
  /// [mqtt] straightness_tolerance_um when > 0).
  std::optional<double> straightness_tolerance_um;
  bool pdf = true;  ///< errsep-scan prints the report to PDF too (headless Chromium)
};

/// Publishing to the plant's MQTT broker ([mqtt], optional; service/plant_publisher.hpp).  The
/// topic tree of one machine is <topic_prefix>/<machine>/{status, scan/<scan id>, alarm,
/// cmd/scan, cmd/scan/reply}; every payload is JSON valid against schema/mqtt-messages.schema.json.
struct MqttConfig {
  std::string host = "127.0.0.1";
  int port = 1883;
  std::string machine;    ///< this machine's name in the topic tree (required)
  std::string client_id;  ///< empty = "errsep-<machine>"
  std::string topic_prefix = "errsep";
  int qos = 1;  ///< 1 or 2: a queued message is removed only once acknowledged
  int keepalive_s = 30;
  std::string username;                               ///< empty = anonymous
  std::filesystem::path password_file;                ///< the password, first line of this file
  std::filesystem::path tls_ca_file;                  ///< set: TLS only (no plain-TCP fallback)
  std::filesystem::path tls_cert_file, tls_key_file;  ///< client certificate (optional, a pair)
  /// Store-and-forward queue; empty = "mqtt-queue" beside the results directory.
  std::filesystem::path queue_dir;
  bool commands = false;  ///< accept <prefix>/<machine>/cmd/scan (same refusals as the coil)
  /// An alarm is published when a scan's minimum-zone straightness exceeds this (0 = none).
  double straightness_tolerance_um = 0.0;

  std::string effective_client_id() const {
    return client_id.empty() ? "errsep-" + machine : client_id;
  }
  /// <topic_prefix>/<machine>
  std::string topic_root() const { return topic_prefix + "/" + machine; }
};

/// The controller tables written from a four-sensor result ([compensation]): the line removed
/// from the error first, the formats and each format's parameters ([compensation.<format>]).
struct CompensationConfig {
  core::CompensationOptions profile;
  CompensationExportOptions tables;
};

/// One harmonic a·sin(2π·x/period + phase) of a simulated profile.
struct Harmonic {
  double amplitude = 0.0;  ///< µm (for gamma: µrad)
  double period_mm = 100.0;
  double phase_rad = 0.0;
};

/// A simulated profile: offset + slope·x + quadratic·x² + Σ harmonics (x in mm).  Units: µm
/// (gamma: µrad).
struct ProfileSpec {
  double offset = 0.0;
  double slope_per_mm = 0.0;
  double quadratic_per_mm2 = 0.0;  ///< a bow: over a travel L its sagitta is quadratic·L²/4
  std::vector<Harmonic> harmonics;
  double eval(double x_mm) const noexcept;
};

/// Fault injection of the device simulator ([simulator.faults] or command line).  Request counts
/// are over all clients, counted from the simulator's start; 0 = never.
struct SimulatorFaults {
  long hang_after_requests = 0;       ///< stop answering after this many requests ...
  int hang_ms = 0;                    ///< ... for this long (0 = forever)
  long drop_after_requests = 0;       ///< close every client connection once, after this many
  long exception_after_requests = 0;  ///< answer with a Modbus exception after this many ...
  int exception_count = 1;            ///< ... for this many requests
  int exception_code = 4;             ///< MODBUS_EXCEPTION_SLAVE_OR_SERVER_FAILURE
  std::string out_of_range_sensor;    ///< this sensor reads range_max_um + 1000 µm
};

/// The device simulator ([simulator]): what it plays, and whether the scan app starts it.
struct SimulatorConfig {
  bool embedded = false;           ///< the scan app starts errsep-devsim itself and uses its port
  std::string host = "127.0.0.1";  ///< loopback only (127.0.0.1 or ::1)
  int port = 0;                    ///< 0 = ephemeral (the actual port is printed)
  /// "zhao2019_example1" (S, gamma, f of Zhao 2019 Eqs. 21-23 for scan.geometry) or "" (use the
  /// profiles below).
  std::string preset = "zhao2019_example1";
  ProfileSpec S_um;                        ///< straightness error S(x)
  ProfileSpec gamma_urad;                  ///< tilt error γ(x), µrad
  ProfileSpec f_um;                        ///< reference surface f(x)
  std::array<double, 4> e_um{0, 0, 0, 0};  ///< zero-adjustment values e_1..e_4 (e_1 = 0)
  /// Gain of each configuration's readings, undeclared to the separation (a fault to find with
  /// the refine step, core/effect_gain.hpp): configuration i reads gain_i · (f + S + O_i γ + e_i).
  std::array<double, 4> gain{1, 1, 1, 1};
  // displacement method (Haramiishi 2024, section 2.1)
  ProfileSpec w_um;  ///< workpiece profile w(x)
  ProfileSpec r_um;  ///< reference piece profile r(x)
  ProfileSpec m_um;  ///< motion error m(x) of the table
  /// A compensation table (any errsep format, io/cnc/compensation_format.hpp) the simulated
  /// controller applies to the output axis as a function of the slide's machine position; empty =
  /// none.  Set by errsep-devsim --compensation (errsep-scan --verify-with).
  std::filesystem::path compensation_table;
  double noise_sigma_um = 0.0;     ///< Gaussian noise on every reading
  double drift_um_per_s = 0.0;     ///< linear sensor drift since the simulator started
  double stage_speed_mm_s = 50.0;  ///< default speed of every simulated stage
  int settle_ms = 20;              ///< time after arrival before in-position is set
  std::uint64_t seed = 1;
  SimulatorFaults faults;
};

struct MachineConfig {
  std::filesystem::path source;  ///< the file it was read from (for messages)
  std::vector<BusConfig> buses;
  std::vector<SensorConfig> sensors;
  std::vector<StageConfig> stages;
  std::optional<GpioConfig> gpio;
  SamplerConfig sampler;
  ScanConfig scan;
  /// [axes]: the machine axes of the scan and the sign of its readings; slide_start_mm is
  /// scan.slide_start_mm.
  core::MachineAxes axes;
  CompensationConfig compensation;
  SeparationConfig separation;
  RefineConfig refine;
  ReportConfig report;
  SimulatorConfig simulator;
  std::optional<MqttConfig> mqtt;  ///< [mqtt]: publish to a broker (absent: do not)

  const BusConfig* find_bus(const std::string& name) const;
  const SensorConfig* find_sensor(const std::string& name) const;
  const StageConfig* find_stage(const std::string& name) const;
  /// Effective sampling rate of a bus (its own, or sampler.rate_hz).
  double sample_rate_hz(const BusConfig& bus) const;
};

/// Reads and validates a machine config.  Throws ConfigError ("file:line: key: problem") on any
/// syntax error, unknown key, wrong type, out-of-range value or dangling reference.
MachineConfig load_machine_config(const std::filesystem::path& file);
/// The same from a string; `name` is used as the file name in messages.
MachineConfig parse_machine_config(const std::string& toml_text, const std::string& name);

/// Things that are allowed but probably not meant, one sentence each (for the scan app to print):
/// a bus whose worst-case request time (1 + retries)·response_timeout_ms exceeds its sample
/// period (a silent device then costs that many periods), RTU sampling faster than a serial line
/// carries, a scan that averages fewer readings than the sampler can give in settle time, ...
std::vector<std::string> config_warnings(const MachineConfig& cfg);

/// For the embedded simulator: every TCP bus whose port is 0 gets `port` (the port the simulator
/// printed as "listening 127.0.0.1:<port>").  Returns how many buses were changed.
int apply_simulator_port(MachineConfig& cfg, int port);

const char* to_string(BusKind k) noexcept;
const char* to_string(StageRole r) noexcept;
const char* to_string(ScanMethod m) noexcept;

}  // namespace errsep::io

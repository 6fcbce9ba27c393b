#pragma once
// The daemon's ScanBackend on real devices (or the device simulator): the drivers a machine
// config describes, scanned by acq::run_scan exactly as errsep-scan scans them (one Sampler thread
// per bus, point retries, the same read-error budget and window time-out) and recorded into the
// daemon's ScanContext cell by cell (ScanHooks::cell), so an interrupted scan leaves every point it
// measured; at the end the scan's own record, with the sampler's counters (missed periods,
// overruns, jitter, real-time set-up), replaces it (ScanContext::finish).
//
// Scan order (Zhao 2019, one sensor on a sensor stage): for each of the four configurations the
// sensor stage moves to sensor_stage_origin_mm + offset_i, then the slide visits x_0..x_p; with
// four fixed probes (single_sensor = false) the slide visits each x_n once and all four are
// averaged together.  scan.method = "displacement" (Haramiishi 2024): the reference piece at its
// origin, then displaced by d, the slide over the displacement points each time; the cells go to
// the ScanContext as acq::ScanHooks::cell numbers them.  "both" is refused at start (one kind of
// scan per trigger).
//
// GPIO: when the config has [gpio] with start_line >= 0, that line (opened with the other devices
// by Devices::configure) is the daemon's start input: a rising edge starts a scan; output_line,
// if set, is on while a scan runs.
#include <memory>
#include <string>

#include "errsep/acq/daemon.hpp"
#include "errsep/drivers/device_factory.hpp"
#include "errsep/io/machine_config.hpp"

namespace errsep::drivers {

class DeviceScanBackend final : public acq::ScanBackend {
 public:
  /// Checks the config can be scanned by the daemon (four_sensor or displacement method, valid
  /// geometry, the scan's stages and sensors present); throws std::runtime_error naming the config
  /// file and key otherwise.  No I/O.
  explicit DeviceScanBackend(io::MachineConfig cfg);
  ~DeviceScanBackend() override;

  /// make_devices + configure (buses, sensors, stages, reconnect supervisor).
  void open() override;
  /// Reads the slide's status word and the first scan sensor once.
  bool check(std::string* why) override;
  acq::ScanEnd run_scan(acq::ScanContext& ctx) override;
  void stop_motion() noexcept override;
  std::string describe() const override;
  /// [gpio] start_line / output_line of the config, once open() succeeded; none otherwise.
  acq::StartInput start_input() override;

 private:
  io::MachineConfig cfg_;
  std::unique_ptr<Devices> dev_;
};

}  // namespace errsep::drivers

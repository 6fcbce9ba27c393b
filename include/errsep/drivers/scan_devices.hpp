#pragma once
// Picks the devices a scan uses out of the drivers a machine config built: the stages and
// sensors named in [scan], each sensor with its bus (one sampling thread per bus).
#include "errsep/acq/scan_runner.hpp"
#include "errsep/drivers/device_factory.hpp"
#include "errsep/io/machine_config.hpp"

namespace errsep::drivers {

/// The ScanDevices of `cfg.scan` for a scan of `kind`.  Pointers refer into `dev`, which must
/// outlive them.  Throws std::runtime_error naming the config key when a named device is
/// missing.  Not real-time safe.
acq::ScanDevices scan_devices(const Devices& dev, const io::MachineConfig& cfg, acq::ScanKind kind);

}  // namespace errsep::drivers

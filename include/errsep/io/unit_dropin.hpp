#pragma once
// The systemd drop-in that lets errsep-daemon reach what its machine config names.  The shipped
// unit (config/errsep.service) allows loopback only (IPAddressDeny=any, IPAddressAllow=localhost):
// "no network beyond what its config names" is kept by allowing exactly the Modbus TCP hosts of
// the config, and the register map's address when it is not loopback, in a drop-in
//   /etc/systemd/system/errsep.service.d/network.conf
// that `errsep-daemon --config X --print-unit-dropin` prints.  Serial (RTU) buses and GPIO need no
// network; their device access is DeviceAllow= in the unit.
#include <string>

#include "errsep/io/machine_config.hpp"

namespace errsep::io {

/// The drop-in's text: a comment naming the config, then [Service] with one IPAddressAllow= per
/// non-loopback address (TCP buses of `cfg`, and `register_map_host` unless it is loopback), or
/// only a comment when loopback is all the daemon needs.  A host that is a name, not an address,
/// is listed as a comment to resolve by hand (IPAddressAllow= takes addresses, not names).
std::string unit_network_dropin(const MachineConfig& cfg, const std::string& register_map_host);

}  // namespace errsep::io

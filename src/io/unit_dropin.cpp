#include "errsep/io/unit_dropin.hpp"

#include <arpa/inet.h>

#include <set>
#include <sstream>
#include <vector>

namespace errsep::io {
namespace {

bool is_address(const std::string& h) {
  unsigned char buf[16];
  return ::inet_pton(AF_INET, h.c_str(), buf) == 1 || ::inet_pton(AF_INET6, h.c_str(), buf) == 1;
}

bool is_loopback(const std::string& h) {
  if (h == "localhost" || h == "::1") return true;
  in_addr a{};
  return ::inet_pton(AF_INET, h.c_str(), &a) == 1 && (ntohl(a.s_addr) >> 24) == 127;
}

}  // namespace

std::string unit_network_dropin(const MachineConfig& cfg, const std::string& register_map_host) {
  std::set<std::string> allow, names;
  std::vector<std::string> why;
  auto add = [&](const std::string& host, const std::string& what) {
    if (is_loopback(host)) return;
    (is_address(host) ? allow : names).insert(host);
    why.push_back(host + ": " + what);
  };
  for (const auto& b : cfg.buses)
    if (b.kind == BusKind::tcp) add(b.host, "Modbus TCP bus '" + b.name + "'");
  if (!register_map_host.empty() && register_map_host != "0.0.0.0" && register_map_host != "::")
    add(register_map_host, "the register map's address (the cell controller reaches it)");
  std::ostringstream os;
  os << "# errsep-daemon's network for " << cfg.source.string() << "\n"
     << "# Install as /etc/systemd/system/errsep.service.d/network.conf, then\n"
     << "#   systemctl daemon-reload && systemctl restart errsep\n";
  if (register_map_host == "0.0.0.0" || register_map_host == "::")
    os << "# The register map listens on every address (" << register_map_host
       << "): allow the cell controller's address below by hand.\n";
  for (const auto& w : why)
    os << "#   " << w << "\n";
  for (const auto& n : names)
    os << "# '" << n << "' is a host name: IPAddressAllow= takes addresses; add its address.\n";
  if (allow.empty() && names.empty()) {
    os << "# Loopback is all this config needs: the unit allows it already, no drop-in needed.\n";
    return os.str();
  }
  os << "[Service]\n";
  for (const auto& a : allow)
    os << "IPAddressAllow=" << a << "\n";
  return os.str();
}

}  // namespace errsep::io

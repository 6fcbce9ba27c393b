#pragma once
// The systemd notification protocol (sd_notify(3)), written here rather than linked from
// libsystemd: one datagram "KEY=value\n..." to the AF_UNIX socket named by $NOTIFY_SOCKET
// (a leading '@' names a socket in the abstract namespace).  Without $NOTIFY_SOCKET (not started
// by systemd with Type=notify) every call is a no-op, so the daemon runs the same in a terminal,
// under systemd and in tests (which set NOTIFY_SOCKET to a socket they read).
//
// Watchdog: $WATCHDOG_USEC (and $WATCHDOG_PID, when set, naming this process) give the interval
// systemd expects a "WATCHDOG=1" within; NOTES.md: ping at half of it.
#include <chrono>
#include <string>
#include <string_view>

namespace errsep::acq {

class SdNotifier {
 public:
  /// Reads $NOTIFY_SOCKET, $WATCHDOG_USEC and $WATCHDOG_PID and opens the datagram socket.
  /// Never throws: a bad or missing socket leaves the notifier disabled (enabled() false, the
  /// reason in error()).  Not real-time safe.
  SdNotifier();
  /// Uses `socket_path` instead of $NOTIFY_SOCKET (empty = disabled) and `watchdog` (0 = none).
  SdNotifier(std::string socket_path, std::chrono::microseconds watchdog);
  ~SdNotifier();
  SdNotifier(const SdNotifier&) = delete;
  SdNotifier& operator=(const SdNotifier&) = delete;

  bool enabled() const noexcept { return fd_ >= 0; }
  /// Why the notifier is disabled although a socket was named ("" otherwise).
  const std::string& error() const noexcept { return error_; }
  /// Interval systemd expects watchdog pings within (0 = no watchdog requested).
  std::chrono::microseconds watchdog_interval() const noexcept { return watchdog_; }

  /// Sends `state` (one or more "KEY=value" lines) as one datagram.  Returns false when disabled
  /// or the send failed (systemd gone: the daemon carries on).  Never blocks: a full receive
  /// queue drops the message rather than stalling the main loop.  Thread-safe (one sendto()).
  bool notify(std::string_view state) const noexcept;
  bool ready() const noexcept { return notify("READY=1"); }
  bool stopping() const noexcept { return notify("STOPPING=1"); }
  bool reloading() const noexcept { return notify("RELOADING=1"); }
  bool watchdog() const noexcept { return notify("WATCHDOG=1"); }
  /// "STATUS=<text>" (newlines in text replaced by spaces: one status line).
  bool status(std::string_view text) const;

 private:
  void open(const std::string& path);
  int fd_ = -1;
  std::string error_;
  std::chrono::microseconds watchdog_{0};
  // sockaddr_un bytes and length, prepared once.
  std::string addr_;
};

}  // namespace errsep::acq

#include "support/daemon_rig.hpp"

#include <catch2/catch.hpp>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "errsep/drivers/daemon_register_server.hpp"
#include "errsep/io/csv.hpp"
#include "errsep/io/results_store.hpp"

extern char** environ;

namespace errsep::test {

Child::Child(const std::vector<std::string>& argv, const std::vector<std::string>& env,
             const std::filesystem::path& stderr_file) {
  int p[2];
  if (::pipe2(p, O_CLOEXEC) != 0) throw std::runtime_error("pipe failed");
  std::vector<std::string> envs;
  for (char** e = environ; *e; ++e)
    envs.emplace_back(*e);
  for (const auto& e : env)
    envs.push_back(e);
  std::vector<char*> av, ev;
  for (const auto& a : argv)
    av.push_back(const_cast<char*>(a.c_str()));
  av.push_back(nullptr);
  for (const auto& e : envs)
    ev.push_back(const_cast<char*>(e.c_str()));
  ev.push_back(nullptr);
  const int err_fd = ::open(stderr_file.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  pid_ = ::fork();
  if (pid_ < 0) throw std::runtime_error("fork failed");
  if (pid_ == 0) {
    ::dup2(p[1], 1);
    if (err_fd >= 0) ::dup2(err_fd, 2);
    ::execve(av[0], av.data(), ev.data());
    ::_exit(127);
  }
  ::close(p[1]);
  if (err_fd >= 0) ::close(err_fd);
  out_fd_ = p[0];
}

Child::~Child() {
  if (running()) {
    ::kill(pid_, SIGKILL);
    wait(std::chrono::milliseconds(5000));
  }
  if (out_fd_ >= 0) ::close(out_fd_);
}

bool Child::running() {
  if (status_) return false;
  int st = 0;
  const pid_t r = ::waitpid(pid_, &st, WNOHANG);
  if (r == pid_) {
    status_ = st;
    return false;
  }
  return r == 0;
}

void Child::signal(int sig) {
  if (running()) ::kill(pid_, sig);
}

std::optional<int> Child::wait(std::chrono::milliseconds timeout) {
  const auto until = std::chrono::steady_clock::now() + timeout;
  while (running()) {
    if (std::chrono::steady_clock::now() >= until) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return status_;
}

std::optional<std::string> Child::read_line(const std::string& prefix,
                                            std::chrono::milliseconds timeout) {
  const auto until = std::chrono::steady_clock::now() + timeout;
  while (true) {
    std::size_t nl;
    while ((nl = buf_.find('\n')) != std::string::npos) {
      std::string line = buf_.substr(0, nl);
      buf_.erase(0, nl + 1);
      if (line.rfind(prefix, 0) == 0) return line.substr(prefix.size());
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        until - std::chrono::steady_clock::now());
    if (left.count() <= 0) return std::nullopt;
    pollfd pfd{out_fd_, POLLIN, 0};
    if (::poll(&pfd, 1, static_cast<int>(left.count())) <= 0) continue;
    char b[512];
    const ssize_t n = ::read(out_fd_, b, sizeof b);
    if (n <= 0) return std::nullopt;  // closed: the child exited
    buf_.append(b, static_cast<std::size_t>(n));
  }
}

double Child::cpu_seconds() const {
  std::ifstream in("/proc/" + std::to_string(pid_) + "/stat");
  std::string s((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto rp = s.rfind(')');
  if (rp == std::string::npos) return -1;
  std::istringstream is(s.substr(rp + 2));
  std::string f;
  // Fields after the command: state(3) ... utime(14) stime(15).
  unsigned long long ut = 0, st = 0;
  for (int i = 3; i <= 15; ++i) {
    is >> f;
    if (i == 14) ut = std::stoull(f);
    if (i == 15) st = std::stoull(f);
  }
  return static_cast<double>(ut + st) / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

NotifyListener::NotifyListener(std::filesystem::path path) : path_(std::move(path)) {
  fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_un sa{};
  sa.sun_family = AF_UNIX;
  if (fd_ < 0 || path_.string().size() >= sizeof sa.sun_path)
    throw std::runtime_error("notify socket: cannot create " + path_.string());
  std::strcpy(sa.sun_path, path_.c_str());
  if (::bind(fd_, reinterpret_cast<sockaddr*>(&sa), sizeof sa) != 0)
    throw std::runtime_error("notify socket: cannot bind " + path_.string());
  thread_ = std::thread([this] {
    char b[4096];
    while (!stop_.load()) {
      pollfd pfd{fd_, POLLIN, 0};
      if (::poll(&pfd, 1, 20) <= 0) continue;
      const ssize_t n = ::recv(fd_, b, sizeof b, MSG_DONTWAIT);
      if (n <= 0) continue;
      std::lock_guard<std::mutex> lock(mu_);
      messages_.emplace_back(b, static_cast<std::size_t>(n));
    }
  });
}

NotifyListener::~NotifyListener() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
  if (fd_ >= 0) ::close(fd_);
  ::unlink(path_.c_str());
}

std::vector<std::string> NotifyListener::messages() const {
  std::lock_guard<std::mutex> lock(mu_);
  return messages_;
}

bool NotifyListener::seen(const std::string& needle) const {
  std::lock_guard<std::mutex> lock(mu_);
  for (const auto& m : messages_)
    if (m.find(needle) != std::string::npos) return true;
  return false;
}

bool NotifyListener::wait_for(const std::string& needle, std::chrono::milliseconds timeout) {
  const auto until = std::chrono::steady_clock::now() + timeout;
  while (!seen(needle)) {
    if (std::chrono::steady_clock::now() >= until) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

int mbpoll_write_coil(int port, int coil, int value, std::string* out) {
  return run_command("/usr/bin/mbpoll -m tcp -a 1 -o 2 -p " + std::to_string(port) +
                         " -t 0 -0 -r " + std::to_string(coil) + " 127.0.0.1 " +
                         std::to_string(value),
                     out);
}

std::vector<long> mbpoll_read_inputs(int port, int start, int count, std::string* out) {
  std::string o;
  const int rc = run_command("/usr/bin/mbpoll -m tcp -a 1 -o 2 -1 -p " + std::to_string(port) +
                                 " -t 3 -0 -r " + std::to_string(start) + " -c " +
                                 std::to_string(count) + " 127.0.0.1",
                             &o);
  if (out) *out = o;
  std::vector<long> regs(static_cast<std::size_t>(count), -1);
  if (rc != 0) return {};
  int found = 0;
  std::istringstream is(o);
  std::string line;
  while (std::getline(is, line)) {
    int idx = 0;
    long v = 0;
    // "[3]: \t13" or "[8]: \t32768 (-32768)"
    if (std::sscanf(line.c_str(), "[%d]: %ld", &idx, &v) == 2 && idx >= start &&
        idx < start + count) {
      regs[static_cast<std::size_t>(idx - start)] = v;
      ++found;
    }
  }
  if (found != count) return {};
  return regs;
}

void Devsim::start(const std::filesystem::path& config, const std::filesystem::path& log, int p) {
  proc = std::make_unique<Child>(
      std::vector<std::string>{app_path("devsim").string(), "-c", config.string(), "--port",
                               std::to_string(p)},
      std::vector<std::string>{}, log);
  const auto rest = proc->read_line("listening 127.0.0.1:", std::chrono::milliseconds(10000));
  if (!rest)
    throw std::runtime_error("errsep-devsim did not print its port (see " + log.string() + ")");
  port = std::stoi(*rest);
}

void Devsim::kill() {
  if (!proc) return;
  proc->signal(SIGKILL);
  proc->wait(std::chrono::milliseconds(5000));
  proc.reset();
}

DaemonRig::DaemonRig()
    : config(source_dir() / "tests/apps/daemon_machine.toml"), results(tmp / "results") {
  notify = std::make_unique<NotifyListener>(tmp / "notify.sock");
}

void DaemonRig::start_daemon(const std::vector<std::string>& extra) {
  std::vector<std::string> argv = {app_path("daemon").string(),
                                   "--config",
                                   config.string(),
                                   "--device-port",
                                   std::to_string(devsim.port),
                                   "--results-dir",
                                   results.string(),
                                   "--modbus-port",
                                   "0",
                                   "--check-ms",
                                   "200"};
  argv.insert(argv.end(), extra.begin(), extra.end());
  argv.insert(argv.begin(), prefix.begin(), prefix.end());
  std::vector<std::string> e = env;
  e.push_back("NOTIFY_SOCKET=" + notify->path().string());
  daemon = std::make_unique<Child>(argv, e, tmp / "daemon.log");
  const auto rest =
      daemon->read_line("register map listening 127.0.0.1:", std::chrono::milliseconds(10000));
  if (!rest)
    throw std::runtime_error("errsep-daemon did not print its register-map port:\n" + logs());
  modbus_port = std::stoi(*rest);
}

std::vector<long> DaemonRig::registers() {
  return mbpoll_read_inputs(modbus_port, 0, static_cast<int>(kRegisterCount));
}

static_assert(kRegisterCount == static_cast<std::size_t>(drivers::kInputRegisterCount),
              "the rig reads the whole register map");

double nm_registers_um(const std::vector<long>& r, int hi) {
  const auto i = static_cast<std::size_t>(hi);
  if (r.size() < i + 2) return std::numeric_limits<double>::quiet_NaN();
  const auto nm = static_cast<std::int32_t>((static_cast<std::uint32_t>(r[i]) << 16) |
                                            static_cast<std::uint32_t>(r[i + 1]));
  if (nm == std::numeric_limits<std::int32_t>::min())
    return std::numeric_limits<double>::quiet_NaN();
  return nm / 1000.0;
}

std::optional<std::filesystem::path> DaemonRig::find_file(std::uint64_t id,
                                                          const std::string& kind) const {
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(results, ec)) {
    const auto f = io::parse_store_name(e.path());
    if (f && f->scan_id == id && f->kind == kind) return e.path();
  }
  return std::nullopt;
}

std::optional<std::filesystem::path> DaemonRig::result_folder(std::uint64_t id) const {
  const auto raw = find_file(id, "raw");
  if (!raw) return std::nullopt;
  const auto f = io::parse_store_name(*raw);
  const auto dir = results / f->stem;
  if (!std::filesystem::is_directory(dir)) return std::nullopt;
  return dir;
}

std::vector<long> DaemonRig::trigger_and_wait(std::uint64_t id, std::chrono::milliseconds timeout) {
  std::string out;
  const int rc = mbpoll_write_coil(modbus_port, 0, 1, &out);
  INFO("mbpoll: " << out);
  REQUIRE(rc == 0);
  const auto r = wait_regs(
      [id](const std::vector<long>& x) {
        return x[reg_last_scan_id] == static_cast<long>(id) && x[reg_state] == 1;
      },
      timeout);
  REQUIRE(r.size() == kRegisterCount);
  return r;
}

namespace {

std::string slurp_file(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

/// "a/b" of points_measured; false when absent or malformed.
bool points_measured(const io::RawFourSensorScan& s, std::size_t& a, std::size_t& b) {
  const auto v = s.meta("points_measured");
  unsigned long x = 0, y = 0;
  char rest = 0;
  if (!v || std::sscanf(v->c_str(), "%lu/%lu%c", &x, &y, &rest) != 2) return false;
  a = x;
  b = y;
  return true;
}

/// The checks shared by raw and raw-incomplete; "" when fine.
std::string check_raw_common(const std::filesystem::path& p, bool complete,
                             io::RawFourSensorScan& s) {
  const std::string bytes = slurp_file(p);
  if (bytes.empty() || bytes.back() != '\n') return "does not end with a newline";
  io::RawReadOptions ro;
  ro.require_complete = complete;
  try {
    s = io::read_raw_four_sensor_csv(p, ro);
  } catch (const std::exception& e) {
    return std::string("does not parse: ") + e.what();
  }
  if (s.complete != complete) return complete ? "not marked complete" : "marked complete";
  if (!s.geometry) return "no geometry";
  const auto P = static_cast<std::size_t>(s.geometry->positions());
  if (s.positions() != P)
    return std::to_string(s.positions()) + " rows, the geometry has " + std::to_string(P) +
           " positions";
  if (!s.t_s) return "no t_i_s columns";
  return {};
}

}  // namespace

std::string check_raw_file(const std::filesystem::path& p, io::RawFourSensorScan* out) {
  io::RawFourSensorScan s;
  if (auto e = check_raw_common(p, true, s); !e.empty()) return e;
  for (std::size_t i = 0; i < 4; ++i)
    for (std::size_t n = 0; n < s.positions(); ++n)
      if (!std::isfinite(s.m_um[i][n]) || !std::isfinite((*s.t_s)[i][n]))
        return "non-finite cell in configuration " + std::to_string(i + 1);
  std::size_t a = 0, b = 0;
  if (!points_measured(s, a, b)) return "no points_measured";
  if (a != 4 * s.positions() || b != a)
    return "points_measured " + *s.meta("points_measured") + " in a complete scan of " +
           std::to_string(s.positions()) + " positions";
  if (out) *out = std::move(s);
  return {};
}

std::string check_checkpoint_file(const std::filesystem::path& p, io::RawFourSensorScan* out) {
  io::RawFourSensorScan s;
  if (auto e = check_raw_common(p, false, s); !e.empty()) return e;
  std::size_t finite = 0, bad_t = 0;
  for (std::size_t i = 0; i < 4; ++i)
    for (std::size_t n = 0; n < s.positions(); ++n) {
      const bool m = std::isfinite(s.m_um[i][n]);
      finite += m ? 1 : 0;
      bad_t += m != std::isfinite((*s.t_s)[i][n]) ? 1 : 0;  // a reading has its time
    }
  std::size_t a = 0, b = 0;
  if (!points_measured(s, a, b)) return "no points_measured";
  if (b != 4 * s.positions())
    return "points_measured " + *s.meta("points_measured") + " of " +
           std::to_string(s.positions()) + " positions";
  if (finite != a || finite == 0)
    return std::to_string(finite) + " finite readings, points_measured " +
           *s.meta("points_measured");
  if (bad_t > 0) return std::to_string(bad_t) + " readings without a time (or times without one)";
  if (out) *out = std::move(s);
  return {};
}

std::string check_result_file(const std::filesystem::path& p, const io::RawFourSensorScan& raw) {
  const std::string bytes = slurp_file(p);
  if (bytes.empty() || bytes.back() != '\n') return "does not end with a newline";
  io::CsvTable t;
  try {
    t = io::read_csv(p);  // every row as wide as the header, every cell a finite number
  } catch (const std::exception& e) {
    return std::string("does not parse: ") + e.what();
  }
  const std::vector<std::string> cols = {"x_mm", "S_um", "gamma_urad", "u_S_um"};
  if (t.columns != cols) return "columns are not x_mm,S_um,gamma_urad,u_S_um";
  if (t.rows.size() != raw.positions())
    return std::to_string(t.rows.size()) + " rows, its raw file has " +
           std::to_string(raw.positions()) + " positions";
  for (std::size_t n = 0; n < t.rows.size(); ++n) {
    if (t.rows[n].size() != cols.size()) return "row " + std::to_string(n) + " is short";
    for (double v : t.rows[n])
      if (!std::isfinite(v)) return "row " + std::to_string(n) + " has a non-finite cell";
    if (std::abs(t.rows[n][0] - raw.x_mm[n]) > 1e-9)
      return "row " + std::to_string(n) + ": x_mm differs from the raw file's";
  }
  if (t.meta("outcome") != std::optional<std::string>("complete")) return "outcome not complete";
  if (!t.meta("straightness_minimum_zone_um") || !t.meta("straightness_least_squares_um"))
    return "no straightness metadata";
  return {};
}

std::vector<long> devsim_inputs(int port, int start, int count) {
  return mbpoll_read_inputs(port, start, count);
}

DaemonRig::~DaemonRig() {
  if (std::uncaught_exceptions() > 0) std::fprintf(stderr, "%s\n", logs().c_str());
}

std::string DaemonRig::logs() const {
  auto slurp = [](const std::filesystem::path& p) {
    std::ifstream in(p);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  };
  return "--- daemon log:\n" + slurp(tmp / "daemon.log") + "--- devsim log:\n" +
         slurp(tmp / "devsim.log");
}

}  // namespace errsep::test

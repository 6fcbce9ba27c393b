#include "errsep/drivers/simulator_process.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

extern char** environ;

namespace errsep::drivers {
namespace {

int wait_exit(pid_t pid, std::chrono::milliseconds timeout) {
  const auto until = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    int status = 0;
    const pid_t r = ::waitpid(pid, &status, WNOHANG);
    if (r == pid) return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    if (r < 0 && errno != EINTR) return -1;
    if (std::chrono::steady_clock::now() >= until) return -2;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

}  // namespace

std::filesystem::path default_devsim_path() {
  std::error_code ec;
  const auto self = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) return {};
  const auto p = self.parent_path() / "errsep-devsim";
  return std::filesystem::exists(p, ec) ? p : std::filesystem::path{};
}

SimulatorProcess::SimulatorProcess(const std::filesystem::path& exe,
                                   const std::filesystem::path& config,
                                   const std::vector<std::string>& extra_args,
                                   std::chrono::milliseconds timeout) {
  if (exe.empty() || ::access(exe.c_str(), X_OK) != 0)
    throw std::runtime_error("device simulator '" + exe.string() +
                             "' not found or not executable (build it: cmake --build build "
                             "--target errsep-devsim)");
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    throw std::runtime_error(std::string("device simulator: pipe: ") + std::strerror(errno));
  std::vector<std::string> args = {exe.string(), "--config", config.string(), "--port", "0"};
  args.insert(args.end(), extra_args.begin(), extra_args.end());
  std::vector<char*> argv;
  for (auto& a : args)
    argv.push_back(a.data());
  argv.push_back(nullptr);

  posix_spawn_file_actions_t fa;
  posix_spawnattr_t attr;
  ::posix_spawn_file_actions_init(&fa);
  ::posix_spawn_file_actions_adddup2(&fa, fds[1], STDOUT_FILENO);
  ::posix_spawnattr_init(&attr);
  // Own process group: the terminal's Ctrl-C goes to the scan, which stops the stages first.
  ::posix_spawnattr_setflags(
      &attr, POSIX_SPAWN_SETPGROUP | POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  ::posix_spawnattr_setpgroup(&attr, 0);
  sigset_t none, deflt;
  sigemptyset(&none);
  sigemptyset(&deflt);
  sigaddset(&deflt, SIGINT);
  sigaddset(&deflt, SIGTERM);
  sigaddset(&deflt, SIGPIPE);
  ::posix_spawnattr_setsigmask(&attr, &none);
  ::posix_spawnattr_setsigdefault(&attr, &deflt);
  const int err = ::posix_spawn(&pid_, exe.c_str(), &fa, &attr, argv.data(), environ);
  ::posix_spawn_file_actions_destroy(&fa);
  ::posix_spawnattr_destroy(&attr);
  ::close(fds[1]);
  if (err != 0) {
    ::close(fds[0]);
    pid_ = -1;
    throw std::runtime_error("device simulator '" + exe.string() +
                             "': cannot start: " + std::strerror(err));
  }
  out_fd_ = fds[0];

  // Read until "listening <host>:<port>\n".
  std::string buf;
  const auto until = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    const auto nl = buf.find('\n');
    if (nl != std::string::npos) {
      const std::string line = buf.substr(0, nl);
      buf.erase(0, nl + 1);
      const std::string key = "listening ";
      const auto k = line.find(key);
      const auto colon = line.rfind(':');
      if (k != std::string::npos && colon != std::string::npos && colon > k) {
        host_ = line.substr(k + key.size(), colon - k - key.size());
        try {
          port_ = std::stoi(line.substr(colon + 1));
        } catch (const std::exception&) {
          port_ = 0;
        }
        if (port_ > 0) break;
      }
      continue;
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        until - std::chrono::steady_clock::now());
    pollfd p{out_fd_, POLLIN, 0};
    const int pr = left.count() > 0 ? ::poll(&p, 1, static_cast<int>(left.count())) : 0;
    if (pr < 0 && errno == EINTR) continue;
    char chunk[256];
    const ssize_t n = pr > 0 ? ::read(out_fd_, chunk, sizeof chunk) : 0;
    if (n > 0) {
      buf.append(chunk, static_cast<std::size_t>(n));
      continue;
    }
    const std::string why =
        pr == 0 ? "did not report a port within " + std::to_string(timeout.count()) + " ms"
                : "exited before reporting a port (see its messages above)";
    stop();
    throw std::runtime_error("device simulator '" + exe.string() + "' " + why);
  }
  drain_ = std::thread([fd = out_fd_] {
    char chunk[256];
    while (::read(fd, chunk, sizeof chunk) > 0) {
    }
  });
}

SimulatorProcess::~SimulatorProcess() {
  stop();
}

int SimulatorProcess::stop() noexcept {
  int rc = -1;
  if (pid_ > 0) {
    ::kill(pid_, SIGTERM);
    rc = wait_exit(pid_, std::chrono::milliseconds(3000));
    if (rc == -2) {
      ::kill(pid_, SIGKILL);
      rc = wait_exit(pid_, std::chrono::milliseconds(3000));
    }
    pid_ = -1;
  }
  if (drain_.joinable()) drain_.join();  // the child's end closed: read() returned 0
  if (out_fd_ >= 0) {
    ::close(out_fd_);
    out_fd_ = -1;
  }
  return rc;
}

}  // namespace errsep::drivers

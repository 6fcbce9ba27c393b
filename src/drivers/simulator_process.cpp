#include "errsep/drivers/simulator_process.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
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

  // Prepared before fork(): the child may only make async-signal-safe calls until exec.
  const pid_t parent = ::getpid();
  struct sigaction dfl {};
  dfl.sa_handler = SIG_DFL;
  sigemptyset(&dfl.sa_mask);
  sigset_t none;
  sigemptyset(&none);
  int err_pipe[2];  // the child's errno when exec fails; closed by a successful exec
  if (::pipe2(err_pipe, O_CLOEXEC) != 0) {
    const int e = errno;
    ::close(fds[0]);
    ::close(fds[1]);
    throw std::runtime_error(std::string("device simulator: pipe: ") + std::strerror(e));
  }
  pid_ = ::fork();
  if (pid_ == 0) {
    // Own process group: the terminal's Ctrl-C goes to the scan, which stops the stages first.
    ::setpgid(0, 0);
    ::sigaction(SIGINT, &dfl, nullptr);
    ::sigaction(SIGTERM, &dfl, nullptr);
    ::sigaction(SIGPIPE, &dfl, nullptr);
    ::sigprocmask(SIG_SETMASK, &none, nullptr);
    // The simulator ends when the program that started it dies, however it dies (SIGKILL, OOM
    // killer, a crash): the kernel sends SIGKILL when the parent thread ends.  A parent that died
    // before this line was not seen by it: the child has been re-parented already, and gives up.
    int e = 0;
    if (::prctl(PR_SET_PDEATHSIG, SIGKILL) != 0) e = errno;
    if (e == 0 && ::getppid() != parent) e = ESRCH;
    if (e == 0 && ::dup2(fds[1], STDOUT_FILENO) < 0) e = errno;
    if (e == 0) {
      ::execve(exe.c_str(), argv.data(), environ);
      e = errno;
    }
    [[maybe_unused]] const ssize_t n = ::write(err_pipe[1], &e, sizeof e);
    ::_exit(127);
  }
  const int fork_err = pid_ < 0 ? errno : 0;
  ::close(err_pipe[1]);
  ::close(fds[1]);
  int child_err = fork_err;
  if (pid_ > 0) {
    ssize_t n;
    while ((n = ::read(err_pipe[0], &child_err, sizeof child_err)) < 0 && errno == EINTR) {
    }
    if (n != static_cast<ssize_t>(sizeof child_err)) child_err = 0;  // exec succeeded
  }
  ::close(err_pipe[0]);
  if (child_err != 0) {
    ::close(fds[0]);
    if (pid_ > 0) ::waitpid(pid_, nullptr, 0);
    pid_ = -1;
    throw std::runtime_error("device simulator '" + exe.string() +
                             "': cannot start: " + std::strerror(child_err));
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

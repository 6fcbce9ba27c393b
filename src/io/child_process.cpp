#include "errsep/io/child_process.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstring>
#include <thread>

extern char** environ;

namespace errsep::io {

int run_child(const ChildRun& run, std::string* why) {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return -1;
  };
  if (run.argv.empty()) return fail("no program given");
  const std::string log = run.log.empty() ? std::string("/dev/null") : run.log.string();
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
  // After the opens, so that a relative log path is taken from here, not from the child's folder.
  if (!run.cwd.empty()) posix_spawn_file_actions_addchdir_np(&fa, run.cwd.c_str());
  std::vector<std::string> args = run.argv;
  std::vector<char*> argv;
  for (auto& a : args)
    argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, args[0].c_str(), &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) return fail("cannot run '" + run.argv[0] + "': " + std::strerror(rc));
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::duration<double>(run.timeout_s > 0 ? run.timeout_s : 0);
  int status = 0;
  for (auto pause = std::chrono::milliseconds(1);;) {
    const pid_t w = waitpid(pid, &status, run.timeout_s > 0 ? WNOHANG : 0);
    if (w == pid) break;
    if (w < 0 && errno != EINTR) return fail(std::string("waitpid: ") + std::strerror(errno));
    if (w == 0 && std::chrono::steady_clock::now() > deadline) {
      ::kill(pid, SIGKILL);
      while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
      }
      return fail("'" + run.argv[0] + "' did not finish within " +
                  std::to_string(static_cast<int>(run.timeout_s)) + " s and was killed");
    }
    if (w == 0) {
      std::this_thread::sleep_for(pause);
      pause = std::min(pause * 2, std::chrono::milliseconds(50));
    }
  }
  if (!WIFEXITED(status)) return fail("'" + run.argv[0] + "' was killed by a signal");
  return WEXITSTATUS(status);
}

}  // namespace errsep::io

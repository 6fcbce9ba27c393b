// errsep-bench-displacement: time and peak memory of the two-axis displacement method's joint
// estimate (one sparse least-squares system, covariance diagonal, rotation decision) for growing
// grids, beside the paper's row-by-row path.  A benchmark, not a test: it prints figures.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <vector>

#include "errsep/core/displacement_simulation.hpp"
#include "errsep/core/two_axis_displacement.hpp"
#include "errsep/version.hpp"

namespace {
using clk = std::chrono::steady_clock;

/// CPU time of this process (user + system), s: on a machine shared with other work the wall
/// time of a run says more about the load than about the code.
double cpu_seconds() {
  timespec ts{};
  ::clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

struct Figures {
  double simulate_s = 0, joint_s = 0, joint_cpu_s = 0, row_by_row_s = 0, u_w_max_um = 0;
  int corrected = 0;
};

/// The example stage (120 mm square) sampled n × n, d = one sample; the paper's noise.
Figures measure(int n, bool row_by_row) {
  using namespace errsep::core;
  TwoAxisSimOptions so;
  so.nx = so.ny = n;
  so.dx_mm = so.dy_mm = so.displacement_x_mm = so.displacement_y_mm = 120.0 / (n - 1);
  so.eddy_sensor.noise_sigma_um = 0.16;
  so.contact_sensor.noise_sigma_um = 0.29;
  Figures f;
  auto t0 = clk::now();
  const auto sim = simulate_two_axis(example_two_axis_truth(), so);
  f.simulate_s = std::chrono::duration<double>(clk::now() - t0).count();
  TwoAxisOptions o;
  o.dx_mm = o.dy_mm = o.displacement_x_mm = o.displacement_y_mm = so.dx_mm;
  t0 = clk::now();
  const double c0 = cpu_seconds();
  const auto res = separate_two_axis(sim.scan, o);
  f.joint_cpu_s = cpu_seconds() - c0;
  f.joint_s = std::chrono::duration<double>(clk::now() - t0).count();
  f.u_w_max_um = res.u_w_um.maxCoeff();
  f.corrected = res.rotation_corrected ? 1 : 0;
  if (row_by_row) {
    o.solver = TwoAxisSolver::row_by_row;
    o.rotation = RotationCorrection::on;
    t0 = clk::now();
    const auto rr = separate_two_axis(sim.scan, o);
    f.row_by_row_s = std::chrono::duration<double>(clk::now() - t0).count() + 0 * rr.w_um(0, 0);
  }
  return f;
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "errsep-bench-displacement: time and peak memory of the two-axis displacement method "
      "(joint estimate with per-point uncertainty) vs grid size"};
  app.set_version_flag("--version", std::string("errsep ") + errsep::kVersion);
  std::vector<int> sizes{25, 200, 1000};
  bool row_by_row = true;
  app.add_option("--n", sizes, "grid sizes n (n x n points)")->capture_default_str();
  app.add_flag("!--no-row-by-row", row_by_row, "skip timing the paper's row-by-row path");
  CLI11_PARSE(app, argc, argv);
  for (int n : sizes)
    if (n < 3) {
      std::fprintf(stderr, "errsep-bench-displacement: --n %d: grids need n >= 3\n", n);
      return 1;
    }

  std::printf("%6s %10s %9s %11s %9s %12s %11s %9s\n", "n", "simulate_s", "joint_s", "joint_cpu_s",
              "peak_MiB", "row_by_row_s", "max_u_w_um", "rotation");
  std::fflush(stdout);
  for (int n : sizes) {
    // Each size in its own process so that the peak resident set is that size's alone (it
    // includes the simulated readings: 9 n² doubles).
    int fds[2];
    if (::pipe(fds) != 0) return 1;
    const pid_t pid = ::fork();
    if (pid == 0) {
      ::close(fds[0]);
      const Figures f = measure(n, row_by_row);
      if (::write(fds[1], &f, sizeof f) != sizeof f) _exit(2);
      _exit(0);
    }
    ::close(fds[1]);
    Figures f;
    const bool got = ::read(fds[0], &f, sizeof f) == sizeof f;
    ::close(fds[0]);
    int status = 0;
    struct rusage ru {};
    ::wait4(pid, &status, 0, &ru);
    if (!got) {
      std::printf("%6d  failed (child status %d)\n", n, status);
      continue;
    }
    std::printf("%6d %10.3f %9.3f %11.3f %9.1f %12.3f %11.3f %9s\n", n, f.simulate_s, f.joint_s,
                f.joint_cpu_s, ru.ru_maxrss / 1024.0, f.row_by_row_s, f.u_w_max_um,
                f.corrected ? "on" : "off");
    std::fflush(stdout);
  }
  std::printf(
      "target (2 cores): n = 1000 joint < 10 s (single-threaded: joint_cpu_s is the time on an "
      "idle core; joint_s includes waiting for a loaded machine)\n");
  return 0;
}

// errsep-bench-four-sensor: times, for growing N, the default estimator (separate_four_sensor with
// its default options: the posterior with a second-difference prior on f, λ by REML on the
// search's grid and golden section, the posterior uncertainties u_S, u_γ, u_f by selected
// inversion — all included) and the paper's L-curve sweep (assembly, one symbolic analysis, ≥ 40
// numeric factorisations + solves, L-curve corner), each in its own process with its peak memory,
// beside a dense SVD-based Tikhonov sweep (what the paper's MATLAB does) where the dense matrix
// fits.  A benchmark, not a test: it prints figures.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <Eigen/Dense>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <vector>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/four_sensor_simulation.hpp"
#include "errsep/core/four_sensor_system.hpp"
#include "errsep/core/lcurve.hpp"
#include "errsep/core/tikhonov_solver.hpp"
#include "errsep/version.hpp"

namespace {
using clk = std::chrono::steady_clock;
double secs(clk::time_point t0) {
  return std::chrono::duration<double>(clk::now() - t0).count();
}
// CPU time of the calling thread: on a shared machine the wall time includes waiting for a core;
// the main thread's CPU time is what the run costs on its critical path (the worker threads run
// beside it), so it estimates the wall time on an idle machine with enough cores.
double thread_cpu_s() {
  timespec t{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

struct Figures {
  double assemble_s = 0, sweep_s = 0, sweep_cpu_s = 0, dense_s = -1, lambda = 0;
  double analyze_s = 0, factorize_s = 0, solve_s = 0;
  int factorizations = 0;
};

// The default estimator end to end (assembly, σ̂, REML search, final factorisation, uncertainties).
struct PosteriorFigures {
  double total_s = 0, total_cpu_s = 0, lambda = 0, edf_f = 0, factorize_s = 0,
         selected_inverse_s = 0;
  int factorizations = 0, fallback = 0;
};

PosteriorFigures measure_posterior(int N, int threads) {
  errsep::core::FourSensorConfig cfg{5.0, 1, 1, 5, N};
  errsep::core::FourSensorSimOptions so;
  so.sigma_um = 0.1;
  const auto sim =
      errsep::core::simulate_four_sensor(cfg, errsep::core::zhao2019_example1(cfg), so);
  errsep::core::FourSensorOptions o;  // the defaults, uncertainties included
  o.search.threads = threads;
  const auto t0 = clk::now();
  const double c0 = thread_cpu_s();
  const auto r = errsep::core::separate_four_sensor(cfg, sim.m_um, o);
  PosteriorFigures f;
  f.total_s = secs(t0);
  f.total_cpu_s = thread_cpu_s() - c0;
  f.lambda = r.lambda;
  f.edf_f = r.edf_f;
  f.factorizations = r.solver_stats.factorizations;
  f.factorize_s = r.solver_stats.factorize_s;
  f.selected_inverse_s = r.solver_stats.selected_inverse_s;
  f.fallback = static_cast<int>(r.lambda_fallback);
  return f;
}

// Runs fn() in a child process (so that the peak resident set is that run's alone) and returns
// its trivially copyable result and the child's peak memory in MiB; false if the child failed.
template <class R, class Fn>
bool in_child(Fn fn, R& out, double& peak_mib, int& status) {
  int fds[2];
  if (::pipe(fds) != 0) return false;
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::close(fds[0]);
    const R r = fn();
    if (::write(fds[1], &r, sizeof r) != sizeof r) _exit(2);
    _exit(0);
  }
  ::close(fds[1]);
  const bool got = ::read(fds[0], &out, sizeof out) == sizeof out;
  ::close(fds[0]);
  struct rusage ru {};
  ::wait4(pid, &status, 0, &ru);
  peak_mib = ru.ru_maxrss / 1024.0;
  return got;
}

Figures measure(int N, int count, bool dense, int threads) {
  errsep::core::FourSensorConfig cfg{5.0, 1, 1, 5, N};
  errsep::core::FourSensorSimOptions so;
  so.sigma_um = 0.1;
  const auto sim =
      errsep::core::simulate_four_sensor(cfg, errsep::core::zhao2019_example1(cfg), so);
  Figures f;
  auto t0 = clk::now();
  auto sys = errsep::core::assemble_four_sensor_system(
      cfg, sim.m_um, errsep::core::CurvatureGauge::sensor_stage_without_curvature);
  f.assemble_s = secs(t0);
  t0 = clk::now();
  const double c0 = thread_cpu_s();
  errsep::core::TikhonovSolver solver(std::move(sys.A), 4);  // Δe: the border columns
  errsep::core::LCurveOptions lo;
  lo.count = count;
  lo.refine_iterations = 0;
  lo.threads = threads;
  const auto lc = errsep::core::lcurve_corner(solver, sys.b, lo);
  f.sweep_s = secs(t0);
  f.sweep_cpu_s = thread_cpu_s() - c0;
  f.lambda = lc.lambda_corner;
  f.factorizations = lc.factorizations;
  f.analyze_s = solver.stats().analyze_s;
  f.factorize_s = solver.stats().factorize_s;
  f.solve_s = solver.stats().solve_s;
  if (dense) {
    t0 = clk::now();
    const Eigen::MatrixXd A(solver.A());
    Eigen::BDCSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeThinU | Eigen::ComputeThinV);
    const Eigen::VectorXd beta = svd.matrixU().transpose() * sys.b;
    const auto& s = svd.singularValues();
    const double lmax = s(0), lmin = lmax * 1e-8;
    double sink = 0;
    for (int i = 0; i < count; ++i) {
      const double l = lmin * std::pow(lmax / lmin, double(i) / (count - 1));
      const Eigen::VectorXd filt = (s.array() / (s.array().square() + l * l)).matrix();
      const Eigen::VectorXd x = svd.matrixV() * filt.cwiseProduct(beta);
      sink += x.norm() + (A * x - sys.b).norm();
    }
    f.dense_s = secs(t0) + 0 * sink;
  }
  return f;
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"errsep-bench-four-sensor: time and peak memory of the lambda sweep vs N"};
  app.set_version_flag("--version", std::string("errsep ") + errsep::kVersion);
  std::vector<int> sizes{69, 1000, 10000, 100000, 1000000};
  int count = 40, dense_max = 2000, threads = 2;
  bool no_sweep = false;
  app.add_option("--N", sizes, "problem sizes")->capture_default_str();
  app.add_option("--lambdas", count, "lambda values in the sweep (>= 40 for the target)")
      ->capture_default_str();
  app.add_option("--dense-max", dense_max, "largest N for the dense SVD baseline")
      ->capture_default_str();
  app.add_option("--threads", threads, "threads for the lambda grid (the target is for 2 cores)")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  app.add_flag("--no-sweep", no_sweep, "time the default estimator only (e.g. for a profile)");
  CLI11_PARSE(app, argc, argv);
  std::printf("lambda grid: %d values, %d thread(s)\n", count, threads);

  std::printf("%9s %10s %12s %12s %10s %11s %9s %8s %12s %12s %12s\n", "N", "assemble_s", "sweep_s",
              "sweep_cpu_s", "analyze_s", "factorize_s", "solve_s", "factor", "peak_MiB", "lambda",
              "dense_svd_s");
  std::fflush(stdout);
  for (int N : no_sweep ? std::vector<int>{} : sizes) {
    Figures f;
    double peak = 0;
    int status = 0;
    if (!in_child([&] { return measure(N, count, N <= dense_max, threads); }, f, peak, status)) {
      std::printf("%9d  failed (child status %d)\n", N, status);
      continue;
    }
    char dense[32] = "-";
    if (f.dense_s >= 0) std::snprintf(dense, sizeof dense, "%.4f", f.dense_s);
    std::printf("%9d %10.4f %12.4f %12.4f %10.4f %11.4f %9.4f %8d %12.1f %12.4g %12s\n", N,
                f.assemble_s, f.sweep_s, f.sweep_cpu_s, f.analyze_s, f.factorize_s, f.solve_s,
                f.factorizations, peak, f.lambda, dense);
    std::fflush(stdout);
  }
  std::printf(
      "\ndefault estimator (posterior, second-difference prior, lambda by REML, %d thread(s); "
      "total = assembly + sigma-hat + search + uncertainties u_S, u_gamma, u_f)\n",
      threads);
  std::printf("%9s %10s %12s %8s %11s %12s %12s %10s %10s %9s\n", "N", "total_s", "total_cpu_s",
              "factor", "factorize_s", "selinv_s", "peak_MiB", "lambda", "edf_f", "fallback");
  std::fflush(stdout);
  for (int N : sizes) {
    PosteriorFigures f;
    double peak = 0;
    int status = 0;
    if (!in_child([&] { return measure_posterior(N, threads); }, f, peak, status)) {
      std::printf("%9d  failed (child status %d)\n", N, status);
      continue;
    }
    std::printf("%9d %10.4f %12.4f %8d %11.4f %12.4f %12.1f %10.4g %10.4g %9s\n", N, f.total_s,
                f.total_cpu_s, f.factorizations, f.factorize_s, f.selected_inverse_s, peak,
                f.lambda, f.edf_f,
                errsep::core::to_string(static_cast<errsep::core::LambdaFallback>(f.fallback)));
    std::fflush(stdout);
  }
  std::printf(
      "*_cpu_s: CPU time of the main thread (the critical path; workers run beside it): the wall "
      "time on an idle machine with a core per thread, when the machine is shared\n"
      "targets (2 cores): N = 1e5 < 0.5 s, N = 1e6 < 5 s (sweep, and the default estimator with "
      "its uncertainties), memory linear in N\n");
  return 0;
}

#include "errsep/acq/realtime.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace errsep::acq {
namespace {

std::string errno_text(int err) {
  std::string s = std::strerror(err);
  if (err == EPERM || err == EACCES)
    s += " (needs CAP_SYS_NICE/CAP_IPC_LOCK or raised RLIMIT_RTPRIO/RLIMIT_MEMLOCK, e.g. "
         "LimitRTPRIO= and LimitMEMLOCK= in the systemd unit; continuing without)";
  else if (err == ENOMEM)
    s += " (RLIMIT_MEMLOCK too low for the process; raise it or run without lock_memory)";
  return s;
}

}  // namespace

bool RealtimeOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (fifo_priority < 0 || fifo_priority > 99)
    return fail("realtime.fifo_priority = " + std::to_string(fifo_priority) +
                ": must be 0 (off) or 1..99");
  if (cpu < -1) return fail("realtime.cpu = " + std::to_string(cpu) + ": must be -1 (off) or >= 0");
  return true;
}

bool RealtimeReport::all_ok() const {
  for (const auto& s : steps)
    if (!s.ok) return false;
  return true;
}

std::string RealtimeReport::brief() const {
  if (steps.empty()) return "none requested";
  std::string out;
  for (const auto& s : steps) {
    if (!out.empty()) out += "; ";
    out += s.step + (s.ok ? " ok" : " failed (" + s.reason + ")");
  }
  return out;
}

RealtimeStep lock_memory() {
  RealtimeStep r{"mlockall", true, {}};
  if (::mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
    r.ok = false;
    r.reason = "mlockall: " + errno_text(errno);
  }
  return r;
}

RealtimeStep set_fifo_priority(int priority) {
  RealtimeStep r{"SCHED_FIFO", true, {}};
  const int lo = ::sched_get_priority_min(SCHED_FIFO), hi = ::sched_get_priority_max(SCHED_FIFO);
  if (priority < lo || priority > hi) {
    r.ok = false;
    r.reason = "priority " + std::to_string(priority) + " outside " + std::to_string(lo) + ".." +
               std::to_string(hi);
    return r;
  }
  sched_param sp{};
  sp.sched_priority = priority;
  // pthread_setschedparam returns the error number instead of setting errno.
  if (const int err = ::pthread_setschedparam(::pthread_self(), SCHED_FIFO, &sp); err != 0) {
    r.ok = false;
    r.reason =
        "pthread_setschedparam(SCHED_FIFO, " + std::to_string(priority) + "): " + errno_text(err);
  }
  return r;
}

RealtimeStep set_cpu_affinity(int cpu) {
  RealtimeStep r{"affinity", true, {}};
  const long ncpu = ::sysconf(_SC_NPROCESSORS_ONLN);
  if (cpu < 0 || (ncpu > 0 && cpu >= ncpu) || cpu >= CPU_SETSIZE) {
    r.ok = false;
    r.reason =
        "CPU " + std::to_string(cpu) + " does not exist (" + std::to_string(ncpu) + " online)";
    return r;
  }
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  if (const int err = ::pthread_setaffinity_np(::pthread_self(), sizeof set, &set); err != 0) {
    r.ok = false;
    r.reason = "pthread_setaffinity_np(CPU " + std::to_string(cpu) + "): " + errno_text(err);
  }
  return r;
}

RealtimeReport apply_realtime(const RealtimeOptions& opts) {
  RealtimeReport rep;
  if (opts.lock_memory) rep.steps.push_back(lock_memory());
  if (opts.fifo_priority > 0) rep.steps.push_back(set_fifo_priority(opts.fifo_priority));
  if (opts.cpu >= 0) rep.steps.push_back(set_cpu_affinity(opts.cpu));
  return rep;
}

}  // namespace errsep::acq

#pragma once
// Real-time set-up of the calling thread: lock memory, SCHED_FIFO priority, CPU affinity.
//
// Each step reports {ok, reason} instead of throwing, because on a stock desktop or in CI the
// process usually lacks CAP_SYS_NICE / CAP_IPC_LOCK (or RLIMIT_RTPRIO / RLIMIT_MEMLOCK): the
// sampler must still run, only with worse jitter, and the scan's metadata must say so.  Only the
// sampling thread is raised, never the whole process (see STYLE.md: no fifo for the service).
#include <string>
#include <vector>

namespace errsep::acq {

struct RealtimeOptions {
  bool lock_memory = false;  ///< mlockall(MCL_CURRENT | MCL_FUTURE): no page faults later
  int fifo_priority = 0;     ///< SCHED_FIFO priority 1..99 for the sampling thread; 0 = leave
  int cpu = -1;              ///< pin the sampling thread to this CPU; -1 = leave

  /// True when usable; otherwise `why` names the field, its value and the constraint.
  bool is_valid(std::string* why = nullptr) const;
};

/// Outcome of one set-up step.  `ok == false` with a reason is a warning for the caller to
/// report (missing privilege), not a failure of the scan.
struct RealtimeStep {
  std::string step;  ///< "mlockall", "SCHED_FIFO", "affinity"
  bool ok = true;
  std::string reason;  ///< empty when ok; otherwise what failed and what to do about it
};

struct RealtimeReport {
  std::vector<RealtimeStep> steps;  ///< only the steps that were requested
  bool all_ok() const;
  /// One line, e.g. "mlockall ok; SCHED_FIFO failed (...)"; "none requested" when empty.
  std::string brief() const;
};

/// mlockall(MCL_CURRENT | MCL_FUTURE).  Not real-time safe (system call that may take long);
/// call before the sampling loop starts.
RealtimeStep lock_memory();
/// Switches the calling thread to SCHED_FIFO at `priority` (1..99).  Not real-time safe; call
/// once on the sampling thread before its loop.
RealtimeStep set_fifo_priority(int priority);
/// Pins the calling thread to `cpu`.  Not real-time safe; call once before the loop.
RealtimeStep set_cpu_affinity(int cpu);
/// Applies the requested steps of `opts` to the calling thread, in the order above.  Never
/// throws for missing privileges.  Not real-time safe (allocates the report).
RealtimeReport apply_realtime(const RealtimeOptions& opts);

}  // namespace errsep::acq

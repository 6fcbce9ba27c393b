#include "support/kill_campaign.hpp"

#include <poll.h>
#include <signal.h>
#include <sys/inotify.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "errsep/io/csv.hpp"
#include "errsep/io/results_store.hpp"
#include "errsep/io/staged_directory.hpp"
#include "support/daemon_rig.hpp"
#include "support/support.hpp"

namespace errsep::test {

namespace fs = std::filesystem;
using clk = std::chrono::steady_clock;
using namespace std::chrono_literals;

namespace {

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

bool is_temporary(const std::string& name) {
  return io::temporary_owner_pid(name) >= 0;
}

void spin_until(clk::time_point t) {
  while (clk::now() < t) {
    // spin: sub-millisecond aim
  }
}

}  // namespace

// ---- DirWatch ----------------------------------------------------------------------------------

DirWatch::DirWatch(const fs::path& dir) : fd_(::inotify_init1(IN_CLOEXEC | IN_NONBLOCK)) {
  if (fd_ < 0 || ::inotify_add_watch(fd_, dir.c_str(), IN_CREATE) < 0) {
    if (fd_ >= 0) ::close(fd_);
    throw std::runtime_error("inotify on " + dir.string() + " failed");
  }
}

DirWatch::~DirWatch() {
  ::close(fd_);
}

bool DirWatch::wait_create(const std::string& needle, int n, std::chrono::milliseconds timeout,
                           const std::string& or_needle) {
  const auto until = clk::now() + timeout;
  int seen = 0;
  alignas(inotify_event) char buf[8192];
  while (clk::now() < until) {
    pollfd pfd{fd_, POLLIN, 0};
    if (::poll(&pfd, 1, 20) <= 0) continue;
    const ssize_t len = ::read(fd_, buf, sizeof buf);
    for (ssize_t off = 0; off < len;) {
      const auto* ev = reinterpret_cast<const inotify_event*>(buf + off);
      off += static_cast<ssize_t>(sizeof(inotify_event) + ev->len);
      const std::string name = ev->len > 0 ? ev->name : "";
      if (name.find(needle) != std::string::npos && ++seen == n) return true;
      if (!or_needle.empty() && name.find(or_needle) != std::string::npos) return true;
    }
  }
  return false;
}

// ---- the daemon's store ------------------------------------------------------------------------

std::string check_store(const fs::path& dir, std::map<std::string, int>& kinds) {
  kinds.clear();
  std::map<std::uint64_t, std::map<std::string, fs::path>> scans;
  for (const auto& e : fs::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    if (is_temporary(name)) {
      ++kinds["temporary"];  // a killed writer's temporary file: not a result, removed at start
      continue;
    }
    if (e.is_directory()) {
      // A scan's result folder (<stem>/, the folder errsep-scan writes): whole, or not there.
      const auto f = io::parse_store_name(dir / (name + ".raw.csv"));
      if (!f) return name + "/: not a scan's result folder";
      const auto c = io::check_result_set(e.path());
      if (!c.whole())
        return name + "/: not a whole result set" +
               (c.problems.empty() ? std::string() : ": " + c.problems.front());
      scans[f->scan_id]["folder"] = e.path();
      ++kinds["folder"];
      continue;
    }
    const auto f = io::parse_store_name(e.path());
    if (!f) return name + ": not a store file";
    scans[f->scan_id][f->kind] = e.path();
    ++kinds[f->kind];
  }
  for (const auto& [id, files] : scans) {
    io::RawFourSensorScan raw;
    bool have_raw = false;
    for (const auto& [kind, path] : files) {
      std::string why;
      if (kind == "raw") {
        why = check_raw_file(path, &raw);
        have_raw = why.empty();
      } else if (kind == "raw-incomplete") {
        io::RawFourSensorScan cp;
        why = check_checkpoint_file(path, &cp);
        // No clean stop happened: every incomplete file is a checkpoint of a running scan.
        if (why.empty() && cp.meta("outcome") != std::optional<std::string>("in_progress"))
          why = "outcome " + cp.meta("outcome").value_or("(none)") + ", not in_progress";
      } else if (kind == "folder") {
        // Its raw file is the scan's, complete: the folder is made from it.
        if (!files.count("raw")) why = "a result folder without its complete raw file";
      } else if (kind != "result") {
        why = "unexpected kind '" + kind + "' (no clean stop happened)";
      }
      if (!why.empty()) return path.filename().string() + ": " + why;
    }
    if (const auto r = files.find("result"); r != files.end()) {
      // A result is written after its raw file, and is of it (raw_crc32: the raw file's CRC).
      if (!have_raw) return r->second.filename().string() + ": no complete raw file beside it";
      // ... and after the scan's result folder, which is whole (checked above).
      if (!files.count("folder"))
        return r->second.filename().string() + ": no result folder beside it";
      std::string why = check_result_file(r->second, raw);
      if (why.empty()) {
        char hex[16];
        std::snprintf(hex, sizeof hex, "%08x", io::file_size_and_crc32(files.at("raw")).second);
        const auto got = io::read_csv(r->second).meta("raw_crc32");
        if (got != std::optional<std::string>(hex))
          why = "of another raw file: raw_crc32 " + got.value_or("(none)") + ", the raw file's " +
                hex;
      }
      if (!why.empty()) return r->second.filename().string() + ": " + why;
    }
  }
  return {};
}

std::string landed_in_store(const fs::path& dir, std::uint64_t id) {
  std::set<std::string> kinds;
  std::string temporary;  // kind of the file whose write was cut
  for (const auto& e : fs::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    if (is_temporary(name)) {
      const auto f = io::parse_store_name(name.substr(1, name.find(".tmp.") - 1));
      if (f && f->scan_id == id) temporary = f->kind;
      continue;
    }
    const auto f = io::parse_store_name(e.path());
    if (f && f->scan_id == id) kinds.insert(f->kind);
    if (e.is_directory())
      if (const auto d = io::parse_store_name(dir / (name + ".raw.csv")); d && d->scan_id == id)
        kinds.insert("folder");
  }
  if (temporary == "raw-incomplete") return "inside a checkpoint's write (temporary left)";
  if (!temporary.empty()) return "inside the " + temporary + " file's write (temporary left)";
  if (kinds.count("result")) return "after the result file";
  if (kinds.count("folder")) return "between the result folder and the result file";
  if (kinds.count("raw") && kinds.count("raw-incomplete"))
    return "between the raw file and the checkpoint's removal";
  if (kinds.count("raw")) return "between the raw and the result file";
  if (kinds.count("raw-incomplete")) return "before the raw file (checkpoint on disk)";
  return "before the first checkpoint";
}

namespace {
/// A /proc file of a process that may exit while it is read: libstdc++'s filebuf throws on the
/// read error (ESRCH, "No such process"), which made the kill campaign fail under load; a
/// process gone is a process not found ("").
std::string slurp_proc(const fs::path& p) {
  try {
    return slurp(p);
  } catch (const std::exception&) {
    return {};
  }
}
}  // namespace

std::vector<pid_t> processes_with(const std::vector<std::string>& needles) {
  std::vector<pid_t> out;
  std::error_code ec;
  for (fs::directory_iterator it("/proc", ec), end; !ec && it != end; it.increment(ec)) {
    const fs::directory_entry& e = *it;
    const std::string name = e.path().filename().string();
    if (name.empty() || !std::all_of(name.begin(), name.end(), ::isdigit)) continue;
    std::string cmd = slurp_proc(e.path() / "cmdline");
    std::replace(cmd.begin(), cmd.end(), '\0', ' ');
    bool all = !cmd.empty();
    for (const auto& n : needles)
      all = all && cmd.find(n) != std::string::npos;
    if (!all) continue;
    const std::string st = slurp_proc(e.path() / "stat");
    const auto rp = st.rfind(')');
    if (rp == std::string::npos || rp + 2 >= st.size()) continue;
    const char state = st[rp + 2];
    if (state == 'Z' || state == 'X') continue;  // dead, waiting to be reaped
    out.push_back(static_cast<pid_t>(std::stol(name)));
  }
  return out;
}

// ---- errsep-scan's result folder ---------------------------------------------------------------

namespace {

/// Every file of a whole set (and of its nested sets): a text file ends with a newline (the
/// report's PNG figures and PDF are binary), a CSV parses and carries the id of the set's run or
/// of a run that extended it (the report errsep-scan adds to its set, io/staged_directory.hpp).
void check_set_files(const fs::path& dir, const io::ResultSetCheck& c, FolderVerdict& v) {
  for (const auto& f : c.files) {
    if (!f.empty() && f.back() == '/') {
      if (!fs::exists(dir / f)) continue;
      const auto sub = io::check_result_set(dir / f);
      check_set_files(dir / f, sub, v);
      continue;
    }
    const fs::path p = dir / f;
    if (!fs::exists(p)) continue;  // the manifest check names it
    const std::string bytes = slurp(p);
    const bool binary = p.extension() == ".png" || p.extension() == ".pdf";
    if (bytes.empty() || (!binary && bytes.back() != '\n')) {
      v.torn = true;
      v.why += p.string() + ": does not end with a newline; ";
      continue;
    }
    if (p.extension() != ".csv") continue;
    io::CsvTable t;
    try {
      io::CsvReadOptions ro;
      ro.allow_non_finite = true;
      ro.min_rows = 0;
      t = io::read_csv(p, ro);
    } catch (const std::exception& e) {
      v.torn = true;
      v.why += std::string(e.what()) + "; ";
      continue;
    }
    const auto id = t.meta("run_id");
    if (!id || std::find(c.run_ids.begin(), c.run_ids.end(), *id) == c.run_ids.end()) {
      v.mixed = true;
      v.why += p.string() + ": run_id " + id.value_or("(none)") + ", the set's " + c.run_id + "; ";
    }
  }
}

}  // namespace

FolderVerdict inspect_scan_folder(const fs::path& out, bool refine) {
  FolderVerdict v;
  if (!fs::exists(out)) return v;
  v.present = true;
  const io::ResultSetCheck c = io::check_result_set(out);
  v.run_id = c.run_id;
  if (!c.has_manifest) {
    v.torn = true;
    v.why = out.string() + ": a folder without a manifest";
    return v;
  }
  check_set_files(out, c, v);
  if (!c.extra.empty()) {  // nobody adds files here: they would be left by another run
    v.mixed = true;
    for (const auto& e : c.extra)
      v.why += e + ": not in the manifest; ";
  }
  if (!c.problems.empty()) {
    // A reader refuses it; a kill must not leave one.  Files of another run (their run_id)
    // count as a mix, anything else as torn.
    if (!v.mixed) v.torn = true;
    for (const auto& p : c.problems)
      v.why += p + "; ";
    return v;
  }
  io::RawReadOptions inspect;
  inspect.require_complete = false;
  io::RawFourSensorScan raw;
  try {
    raw = io::read_raw_four_sensor_csv(out / "raw.csv", inspect);
  } catch (const std::exception& e) {
    v.torn = true;
    v.why += std::string("raw.csv: ") + e.what() + "; ";
    return v;
  }
  if (raw.complete) {
    std::vector<std::string> want = {"motion.csv", "reference.csv", "lcurve.csv", "residuals.csv",
                                     "summary.txt"};
    if (refine) want.push_back("refine/");
    std::string missing;
    for (const auto& w : want)
      if (std::find(c.files.begin(), c.files.end(), w) == c.files.end()) missing += " " + w;
    if (!missing.empty()) {
      v.partial_accepted = true;
      v.why += "a complete raw.csv without" + missing + ", and the set is whole; ";
    }
  }
  return v;
}

// ---- the campaign ------------------------------------------------------------------------------

std::string KillCounts::table() const {
  std::ostringstream os;
  const int kills = scan_kills + daemon_kills;
  os << kills << " SIGKILLs: " << scan_kills << " of errsep-scan (" << scan_fresh
     << " into a fresh --out folder, " << scan_overwritten
     << " into one holding an earlier result; " << scan_aimed_write
     << " aimed into the end-of-scan writes, " << scan_aimed_commit
     << " at the commit, the rest at a random moment; " << scan_landed_writing
     << " landed after the raw file's write began), " << daemon_kills
     << " of errsep-daemon during scans triggered through its start coil (" << daemon_aimed_write
     << " aimed at the raw file's write); " << unkilled_runs
     << " runs ended before their kill or were the final checks\n";
  os << "| check | result |\n|---|---|\n";
  os << "| torn or half-written files | " << torn << " |\n";
  os << "| a file reported as written, then missing | " << reported_missing << " |\n";
  os << "| the next run fails | " << next_run_failed << " |\n";
  os << "| daemon: temporaries of the killed life removed at restart, results recovered from "
        "complete raw files | "
     << (daemon_not_recovered == 0 ? std::string("all")
                                   : std::to_string(daemon_not_recovered) + " restarts not")
     << " |\n";
  os << "| errsep-scan: the errsep-devsim it started is left running | " << children_left << " of "
     << scan_kills << " kills |\n";
  os << "| result folder holds raw.csv plus only some of the result files, and a reader accepts "
        "it | "
     << partial_accepted << " |\n";
  os << "| result folder mixes two runs | " << mixed << " |\n";
  os << "| temporaries left by a kill and never removed by later runs | " << temporaries_left
     << " |\n";
  return os.str();
}

int KillCounts::zeros_broken() const {
  return torn + reported_missing + next_run_failed + daemon_not_recovered + children_left +
         partial_accepted + mixed + temporaries_left;
}

namespace {

void fail(KillCounts& k, const std::string& what) {
  if (k.failures.size() < 20) k.failures.push_back(what);
}

/// The embedded default config, made quick: N = 20 (13 positions, 52 points), fast stages: a run
/// takes ~0.7 s.
fs::path write_scan_config(const fs::path& dir) {
  std::string t = slurp(source_dir() / "config" / "simulator.toml");
  auto replace_all = [&](const std::string& from, const std::string& to) {
    for (auto p = t.find(from); p != std::string::npos; p = t.find(from, p + to.size()))
      t.replace(p, from.size(), to);
  };
  replace_all("N = 69", "N = 20");
  // Loopback answers in well under a millisecond, but not always on a loaded CI machine: a device
  // time-out there is not what this campaign is about.
  replace_all("response_timeout_ms = 20 ", "response_timeout_ms = 500 ");
  replace_all("response_timeout_ms = 100\n", "response_timeout_ms = 1000\n");
  replace_all("speed_mm_s = 200.0", "speed_mm_s = 4000.0");
  replace_all("speed_mm_s = 100.0", "speed_mm_s = 4000.0");
  const fs::path p = dir / "scan-machine.toml";
  std::ofstream(p) << t;
  return p;
}

struct Lane {
  std::string name;
  fs::path parent, out;
  bool fresh = false, refine = false;
  double run_s = 1.0, write_s = 0.05;  // calibrated: spawn to exit, raw file's write to exit
  std::vector<pid_t> pending;          // killed runs whose temporaries the next run must remove
};

struct ScanOutcome {
  bool killed = false;        ///< the kill reached a running process
  bool exited_ok = false;     ///< ended by itself with status 0
  bool passed_sweep = false;  ///< got past the removal of stale temporaries
  pid_t pid = -1;
  std::string stdout_text;
  double run_s = 0, write_s = -1;
};

ScanOutcome run_scan_once(const Lane& lane, const fs::path& cfg, const fs::path& log,
                          const std::string& aim, std::mt19937& rng) {
  std::vector<std::string> argv = {app_path("scan").string(),
                                   "--config",
                                   cfg.string(),
                                   "--out",
                                   lane.out.string(),
                                   "--devsim",
                                   app_path("devsim").string(),
                                   "--averages",
                                   "2",
                                   "--settle-ms",
                                   "0"};
  if (lane.refine) argv.push_back("--refine");
  ScanOutcome o;
  const auto t0 = clk::now();
  Child proc(argv, {}, log);
  o.pid = proc.pid();
  const fs::path stage = lane.parent / ("." + lane.out.filename().string() + ".scan-partial-" +
                                        std::to_string(proc.pid()));
  // Watch the staging folder from its creation (the first thing the scan does).
  std::unique_ptr<DirWatch> watch;
  while (!watch && proc.running() && clk::now() - t0 < 20s) {
    if (fs::exists(stage)) {
      try {
        watch = std::make_unique<DirWatch>(stage);
      } catch (const std::exception&) {
        // removed again in between (the run failed): no watch
      }
    }
    if (!watch) std::this_thread::sleep_for(200us);
  }
  clk::time_point kill_at = clk::time_point::max();
  clk::time_point write_began = clk::time_point::max();
  if (aim == "random") {
    std::uniform_real_distribution<double> u(0.0, lane.run_s);
    kill_at = t0 + std::chrono::duration_cast<clk::duration>(std::chrono::duration<double>(u(rng)));
  } else if (watch && (aim == "write" || aim == "calibrate")) {
    if (watch->wait_create(".raw.csv.tmp.", 1, 30s)) write_began = clk::now();
    if (aim == "write") {
      std::uniform_real_distribution<double> u(0.0, lane.write_s);
      kill_at = write_began +
                std::chrono::duration_cast<clk::duration>(std::chrono::duration<double>(u(rng)));
    }
  } else if (watch && aim == "commit") {
    if (watch->wait_create(".errsep-manifest.txt.tmp.", 1, 30s)) {
      std::uniform_int_distribution<int> u(0, 2000);
      kill_at = clk::now() + std::chrono::microseconds(u(rng));
    }
  }
  if (kill_at != clk::time_point::max()) {
    while (proc.running() && clk::now() + 2ms < kill_at)
      std::this_thread::sleep_for(1ms);
    spin_until(kill_at);
    if (proc.running()) {
      proc.signal(SIGKILL);
      o.killed = true;
    }
  }
  const auto st = proc.wait(120s);
  const auto t1 = clk::now();
  o.run_s = std::chrono::duration<double>(t1 - t0).count();
  if (write_began != clk::time_point::max())
    o.write_s = std::chrono::duration<double>(t1 - write_began).count();
  if (!o.killed && st && WIFSIGNALED(*st) && WTERMSIG(*st) == SIGKILL) o.killed = true;
  o.exited_ok = !o.killed && st && WIFEXITED(*st) && WEXITSTATUS(*st) == 0;
  // Everything it printed (the pipe closes when it dies; its simulator never held it).
  std::string text;
  while (auto line = proc.read_line("", 2s))
    text += *line + "\n";
  o.stdout_text = text;
  o.passed_sweep = text.find("device simulator: pid") != std::string::npos || o.exited_ok;
  return o;
}

/// Paths a run said it wrote: "raw data: P", "results: D/ (...)", "refine: D/ (...)".
std::vector<fs::path> reported_paths(const std::string& text) {
  std::vector<fs::path> out;
  std::istringstream is(text);
  std::string line;
  while (std::getline(is, line)) {
    for (const std::string key : {"raw data: ", "results: ", "refine: "}) {
      if (line.rfind(key, 0) != 0) continue;
      std::string p = line.substr(key.size());
      p = p.substr(0, p.find(' '));
      // "refine: model ..." is the refine step's summary, not a path: folders end with '/'.
      if (key != "raw data: " && (p.empty() || p.back() != '/')) continue;
      if (p.back() == '/') p.pop_back();
      out.emplace_back(p);
    }
  }
  return out;
}

/// What dead errsep processes in `pids` left in the lane's folders.
int temporaries_of(const Lane& lane, const std::vector<pid_t>& pids, std::string* names) {
  int n = 0;
  for (const auto& dir : {lane.parent, lane.out}) {
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) continue;
    for (const auto& e : fs::directory_iterator(dir, ec)) {
      const long owner = io::temporary_owner_pid(e.path().filename().string());
      if (owner > 0 && std::find(pids.begin(), pids.end(), owner) != pids.end()) {
        ++n;
        *names += e.path().string() + " ";
      }
    }
  }
  return n;
}

void scan_trial(Lane& lane, const fs::path& cfg, const fs::path& log, const std::string& aim,
                std::mt19937& rng, KillCounts& k, bool final_run) {
  const std::size_t log_before = fs::exists(log) ? fs::file_size(log) : 0;
  const ScanOutcome o = run_scan_once(lane, cfg, log, final_run ? "calibrate" : aim, rng);
  const std::string label = lane.name + " lane, " + (final_run ? "final run" : aim + " kill");
  if (o.killed) {
    ++k.scan_kills;
    ++(lane.fresh ? k.scan_fresh : k.scan_overwritten);
    if (aim == "write") ++k.scan_aimed_write;
    if (aim == "commit") ++k.scan_aimed_commit;
    if (aim == "write" || aim == "commit") ++k.scan_landed_writing;
  } else {
    ++k.unkilled_runs;
    if (!o.exited_ok) {
      ++k.next_run_failed;
      const std::string l = slurp(log);
      fail(k, label + ": the run failed:\n" + l.substr(std::min(log_before, l.size())));
    }
  }
  // The simulator it started ends with it: allow the kernel a moment to deliver the signal and
  // the dying process to be scheduled (1 s was crossed once on a machine at load 16; a simulator
  // that really outlives its scan runs on for ever, so the wait does not hide one).
  if (o.killed) {
    std::vector<pid_t> left;
    for (const auto until = clk::now() + 5s; clk::now() < until;) {
      left = processes_with({"errsep-devsim", cfg.string()});
      if (left.empty()) break;
      std::this_thread::sleep_for(10ms);
    }
    if (!left.empty()) {
      ++k.children_left;
      fail(k, label + ": errsep-devsim pid " + std::to_string(left[0]) +
                  " still running 5 s after its errsep-scan was killed");
      for (pid_t p : left)
        ::kill(p, SIGKILL);
    }
  }
  // What was reported as written is there, whole.
  for (const auto& p : reported_paths(o.stdout_text)) {
    std::error_code ec;
    if (!fs::exists(p, ec)) {
      ++k.reported_missing;
      fail(k, label + ": reported " + p.string() + ", which is missing");
    }
  }
  // The folder, as a reader sees it.
  const FolderVerdict v = inspect_scan_folder(lane.out, lane.refine);
  if (!lane.fresh && !v.present) {
    ++k.reported_missing;  // the earlier run's result, reported written by it, is gone
    fail(k, label + ": the earlier result folder is gone");
  }
  if (v.torn) ++k.torn;
  if (v.mixed) ++k.mixed;
  if (v.partial_accepted) ++k.partial_accepted;
  if (v.torn || v.mixed || v.partial_accepted) fail(k, label + ": " + v.why);
  if (final_run && (!v.present || !o.exited_ok)) {
    ++k.next_run_failed;
    fail(k, label + ": no result after an unkilled run");
  }
  // The temporaries of earlier kills are gone once a run got past its start.
  if (o.passed_sweep && !lane.pending.empty()) {
    std::string names;
    if (const int n = temporaries_of(lane, lane.pending, &names); n > 0) {
      k.temporaries_left += n;
      fail(k, label + ": temporaries of killed runs left after the next run: " + names);
    }
    lane.pending.clear();
  }
  if (o.killed) lane.pending.push_back(o.pid);  // what it left is for the next run to remove
  if (lane.fresh && v.present) fs::remove_all(lane.out);  // the next one is fresh
}

}  // namespace

KillCounts run_kill_campaign(const KillCampaignOptions& opts) {
  KillCounts k;
  TempDir tmp;
  std::mt19937 rng(opts.seed);
  const fs::path cfg = write_scan_config(tmp.path());
  const fs::path log = tmp / "scan.log";
  const auto t_start = clk::now();

  // ---- errsep-scan ----
  Lane fresh, over;
  fresh.name = "fresh";
  fresh.parent = tmp / "fresh";
  fresh.fresh = true;
  over.name = "overwritten";
  over.parent = tmp / "over";
  over.refine = opts.refine;
  fresh.out = fresh.parent / "out";
  over.out = over.parent / "out";
  for (Lane* lane : {&fresh, &over}) {
    fs::create_directories(lane->parent);
    // Calibration: two unkilled runs (the first starts cold); for the overwritten lane they
    // leave the earlier result.
    for (int c = 0; c < 2; ++c) {
      const ScanOutcome o = run_scan_once(*lane, cfg, log, "calibrate", rng);
      if (!o.exited_ok || o.write_s < 0)
        throw std::runtime_error("errsep-scan calibration run failed:\n" + slurp(log) +
                                 o.stdout_text);
      lane->run_s = o.run_s;
      lane->write_s = o.write_s;
      if (lane->fresh) fs::remove_all(lane->out);
    }
  }
  const char* aims[] = {"random", "write", "commit", "write"};
  const auto scan_budget = opts.budget * 3 / 4;
  // Until the kills are made (a random moment may fall after a run's end: it is not a kill).
  for (int i = 0; k.scan_kills < opts.scan_kills && i < 2 * opts.scan_kills; ++i) {
    if (k.scan_kills >= 8 && clk::now() - t_start > scan_budget) break;
    Lane& lane = i % 2 == 0 ? fresh : over;
    const std::string aim = aims[(i / 2) % 4];
    scan_trial(lane, cfg, log, aim, rng, k, false);
  }
  for (Lane* lane : {&fresh, &over})
    scan_trial(*lane, cfg, log, "final", rng, k, true);

  // ---- errsep-daemon ----
  DaemonRig rig;
  {
    std::string c = slurp(rig.config);
    for (const auto& [from, to] : std::vector<std::pair<std::string, std::string>>{
             {"speed_mm_s = 400.0", "speed_mm_s = 4000.0"},
             {"\naverages = 5", "\naverages = 2"},
             {"\nsettle_ms = 2", "\nsettle_ms = 0"},
             {"response_timeout_ms = 20\n", "response_timeout_ms = 500\n"},
             {"response_timeout_ms = 100\n", "response_timeout_ms = 1000\n"}})
      for (auto p = c.find(from); p != std::string::npos; p = c.find(from, p + to.size()))
        c.replace(p, from.size(), to);
    rig.config = rig.tmp / "machine-fast.toml";
    std::ofstream(rig.config) << c;
  }
  rig.devsim.start(rig.config, rig.tmp / "devsim.log");
  const fs::path dlog = rig.tmp / "daemon.log";
  pid_t killed_daemon = -1;
  auto check_restart = [&](const std::string& label) {
    // A restarted daemon has removed the killed life's temporaries and made the result of every
    // complete raw file.
    std::string bad;
    std::set<std::string> raws, results;
    for (const auto& e : fs::directory_iterator(rig.results)) {
      const std::string name = e.path().filename().string();
      if (killed_daemon > 0 && io::temporary_owner_pid(name) == killed_daemon)
        bad += name + " (a temporary of the killed life) ";
      if (const auto f = io::parse_store_name(e.path())) {
        if (f->kind == "raw") raws.insert(f->stem);
        if (f->kind == "result") results.insert(f->stem);
      }
    }
    for (const auto& r : raws)
      if (!results.count(r)) bad += r + ".raw.csv without its result ";
    if (!bad.empty()) {
      ++k.daemon_not_recovered;
      fail(k, label + ": after the restart: " + bad);
    }
  };
  const auto daemon_start = clk::now();
  const auto daemon_budget =
      opts.budget - std::chrono::duration_cast<std::chrono::seconds>(daemon_start - t_start);
  for (int i = 0; i <= opts.daemon_kills; ++i) {
    const bool final_life =
        i == opts.daemon_kills || (i >= 8 && clk::now() - daemon_start > daemon_budget);
    const std::string label = "daemon life " + std::to_string(i);
    const std::size_t log_before = fs::exists(dlog) ? fs::file_size(dlog) : 0;
    rig.notify = std::make_unique<NotifyListener>(rig.tmp / ("notify" + std::to_string(i)));
    try {
      rig.start_daemon({"--checkpoint-ms", "50"});
    } catch (const std::exception& e) {
      ++k.next_run_failed;
      fail(k, label + ": " + e.what());
      break;
    }
    if (!rig.notify->wait_for("READY=1", 15s)) {
      ++k.next_run_failed;
      fail(k, label + ": no READY=1 within 15 s:\n" + rig.logs());
      break;
    }
    if (i > 0) check_restart(label);
    if (final_life) {
      ++k.unkilled_runs;
      rig.daemon->signal(SIGTERM);
      rig.daemon->wait(10s);
      break;
    }
    const std::uint64_t id = io::ResultsStore({rig.results, 0, {}}).next_scan_id();
    DirWatch watch(rig.results);
    if (mbpoll_write_coil(rig.modbus_port, 0, 1) != 0) {
      ++k.next_run_failed;
      fail(k, label + ": the start coil was not accepted");
      break;
    }
    const bool aimed = i % 2 == 1;
    clk::time_point kill_at;
    if (aimed) {
      watch.wait_create(".raw.csv.tmp.", 1, 20s);
      kill_at =
          clk::now() + std::chrono::microseconds(std::uniform_int_distribution<int>(0, 3000)(rng));
      ++k.daemon_aimed_write;
    } else {
      kill_at =
          clk::now() + std::chrono::milliseconds(std::uniform_int_distribution<int>(0, 400)(rng));
    }
    spin_until(kill_at);
    killed_daemon = rig.daemon->pid();
    rig.daemon->signal(SIGKILL);
    rig.daemon->wait(5s);
    ++k.daemon_kills;
    if (!processes_with({"errsep-daemon", rig.results.string()}).empty()) {
      ++k.children_left;
      fail(k, label + ": an errsep-daemon is still running after the kill");
    }
    rig.daemon.reset();
    // Whole files, each result of its raw file.
    std::map<std::string, int> kinds;
    const std::string why = check_store(rig.results, kinds);
    if (!why.empty()) {
      if (why.find("of another raw file") != std::string::npos)
        ++k.mixed;
      else
        ++k.torn;
      fail(k, label + " (" + landed_in_store(rig.results, id) + "): " + why);
    }
    // What this life logged as written is there.
    const std::string l = slurp(dlog).substr(log_before);
    std::istringstream is(l);
    std::string line;
    while (std::getline(is, line)) {
      const auto w = line.rfind("wrote ");
      if (w == std::string::npos) continue;
      const fs::path p = line.substr(w + 6);
      if (!fs::exists(p)) {
        ++k.reported_missing;
        fail(k, label + ": logged '" + line + "', the file is missing");
      }
    }
  }
  return k;
}

}  // namespace errsep::test

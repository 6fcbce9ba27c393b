#include "errsep/io/staged_directory.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <boost/crc.hpp>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <stdexcept>

#include "errsep/io/atomic_file.hpp"

namespace errsep::io {

namespace fs = std::filesystem;

namespace {

constexpr const char* kPartial = "-partial-";

bool hidden(const fs::path& p) {
  const std::string n = p.filename().string();
  return !n.empty() && n[0] == '.';
}

std::string utc_stamp(const char* format) {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  ::gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, format, &tm);
  return buf;
}

std::string make_run_id() {
  std::random_device rd;
  char tail[8];
  std::snprintf(tail, sizeof tail, "%04x", static_cast<unsigned>(rd() & 0xFFFFu));
  return utc_stamp("%Y%m%dT%H%M%SZ") + "-" + std::to_string(::getpid()) + "-" + tail;
}

void fsync_dir(const fs::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd >= 0) {
    ::fsync(fd);
    ::close(fd);
  }
}

/// The non-hidden entries of a folder, sorted (a set lists its files in a fixed order).
std::vector<fs::directory_entry> entries(const fs::path& dir) {
  std::vector<fs::directory_entry> out;
  for (const auto& e : fs::directory_iterator(dir))
    if (!hidden(e.path())) out.push_back(e);
  std::sort(out.begin(), out.end(),
            [](const auto& a, const auto& b) { return a.path().filename() < b.path().filename(); });
  return out;
}

struct Manifest {
  std::string kind, run_id, writer, created_utc;
  /// "<run id> <UTC> <writer>" of each run that added files to the set (errsep-report), and
  /// "adopted <UTC> <writer>" when a writer took a folder without a manifest as found.
  std::vector<std::string> extended;
  struct File {
    std::string path;
    std::uintmax_t bytes = 0;
    std::uint32_t crc = 0;
  };
  std::vector<File> files;
  std::vector<std::pair<std::string, std::string>> sets;  ///< relative path, its run id
};

/// Parses dir/errsep-manifest.txt; problems go to `why` (empty = parsed).
Manifest read_manifest(const fs::path& dir, std::string* why) {
  Manifest m;
  const fs::path file = dir / kManifestName;
  std::ifstream in(file);
  if (!in) {
    *why = std::string(kManifestName) + ": cannot be read";
    return m;
  }
  std::string line;
  std::size_t lineno = 0;
  long expected = -1;
  bool ended = false;
  auto bad = [&](const std::string& what) {
    if (why->empty())
      *why = std::string(kManifestName) + ":" + std::to_string(lineno) + ": " + what;
  };
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#') continue;
    if (ended) {
      bad("text after 'end'");
      break;
    }
    std::istringstream ls(line);
    std::string word;
    ls >> word;
    auto rest = [&]() {
      std::string r;
      std::getline(ls, r);
      const auto b = r.find_first_not_of(' ');
      return b == std::string::npos ? std::string() : r.substr(b);
    };
    if (word == "kind:")
      m.kind = rest();
    else if (word == "run_id:")
      m.run_id = rest();
    else if (word == "writer:")
      m.writer = rest();
    else if (word == "created_utc:")
      m.created_utc = rest();
    else if (word == "extended:")
      m.extended.push_back(rest());
    else if (word == "entries:") {
      if (!(ls >> expected)) bad("'entries:' needs a number");
    } else if (word == "file") {
      Manifest::File f;
      std::string crc;
      if (!(ls >> f.bytes >> crc)) {
        bad("'file' needs a size, a CRC-32 and a path");
        continue;
      }
      f.crc = static_cast<std::uint32_t>(std::strtoul(crc.c_str(), nullptr, 16));
      f.path = rest();
      if (f.path.empty()) bad("'file' without a path");
      m.files.push_back(std::move(f));
    } else if (word == "set") {
      std::string id;
      ls >> id;
      std::string p = rest();
      if (p.empty()) bad("'set' without a path");
      m.sets.emplace_back(std::move(p), std::move(id));
    } else if (word == "end") {
      ended = true;
    } else {
      bad("unknown line '" + line + "'");
    }
  }
  if (why->empty() && !ended) bad("no 'end' line: the manifest is cut short");
  if (why->empty() && expected != static_cast<long>(m.files.size() + m.sets.size()))
    bad("lists " + std::to_string(m.files.size() + m.sets.size()) + " entries, says " +
        std::to_string(expected));
  if (why->empty() && m.kind.empty()) bad("no 'kind:'");
  return m;
}

/// The files and nested sets below `dir` (relative to `root`), as a manifest lists them.
void collect(const fs::path& root, const fs::path& dir, Manifest& m) {
  for (const auto& e : entries(dir)) {
    const std::string rel = e.path().lexically_relative(root).generic_string();
    if (e.is_symlink())
      throw std::runtime_error("'" + e.path().string() + "': a symbolic link cannot be in a set");
    if (e.is_directory()) {
      fsync_dir(e.path());
      if (fs::exists(e.path() / kManifestName)) {
        std::string why;
        const Manifest nested = read_manifest(e.path(), &why);
        if (!why.empty())
          throw std::runtime_error("'" + e.path().string() + "': nested set: " + why);
        m.sets.emplace_back(rel + "/", nested.run_id);
      } else {
        collect(root, e.path(), m);
      }
    } else if (e.is_regular_file()) {
      if (dir == root && e.path().filename() == kManifestName) continue;
      const auto [bytes, crc] = file_size_and_crc32(e.path());
      m.files.push_back({rel, bytes, crc});
    }
  }
}

std::string format_manifest(const Manifest& m) {
  std::ostringstream os;
  os << "# errsep result set: every file of the set with its size in bytes and CRC-32; a\n"
        "# sub-folder that is a set of its own is listed as 'set <its run id> <path>/'.\n"
        "# Written last; a reader refuses the folder when a file is missing or differs.\n";
  os << "kind: " << m.kind << "\nrun_id: " << m.run_id << "\nwriter: " << m.writer
     << "\ncreated_utc: " << m.created_utc << "\n";
  for (const auto& e : m.extended)
    os << "extended: " << e << "\n";
  os << "entries: " << m.files.size() + m.sets.size() << "\n";
  char crc[16];
  for (const auto& f : m.files) {
    std::snprintf(crc, sizeof crc, "%08x", f.crc);
    os << "file " << f.bytes << " " << crc << " " << f.path << "\n";
  }
  for (const auto& [p, id] : m.sets)
    os << "set " << (id.empty() ? "-" : id) << " " << p << "\n";
  os << "end\n";
  return os.str();
}

/// Hard links (or copies, across file systems) of the files below `from` into `to`.
void link_tree(const fs::path& from, const fs::path& to, const std::vector<std::string>& skip) {
  for (const auto& e : entries(from)) {
    const std::string name = e.path().filename().string();
    if (std::find(skip.begin(), skip.end(), name) != skip.end()) continue;
    if (e.is_directory()) {
      fs::create_directory(to / name);
      link_tree(e.path(), to / name, {});
    } else if (e.is_regular_file()) {
      std::error_code ec;
      fs::create_hard_link(e.path(), to / name, ec);
      if (ec) fs::copy_file(e.path(), to / name);
    }
  }
}

bool pid_alive_since(long pid, fs::file_time_type made) {
  if (pid <= 0) return false;
  if (pid == static_cast<long>(::getpid())) return true;
  if (::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH) return false;
  // The pid exists: is it the process that made the temporary, or a later one with its number?
  std::ifstream st("/proc/" + std::to_string(pid) + "/stat");
  std::string s((std::istreambuf_iterator<char>(st)), std::istreambuf_iterator<char>());
  const auto close = s.rfind(')');
  if (close == std::string::npos) return true;  // cannot tell: keep it
  std::istringstream fields(s.substr(close + 2));
  std::string state;
  fields >> state;
  if (state == "Z" || state == "X") return false;  // dead, not yet reaped
  std::string skip;
  for (int i = 0; i < 18; ++i)  // fields 4..21; field 22 is the start time
    fields >> skip;
  unsigned long long start_ticks = 0;
  if (!(fields >> start_ticks)) return true;
  std::ifstream up("/proc/uptime");
  double uptime_s = 0;
  if (!(up >> uptime_s)) return true;
  const double age_s =
      uptime_s - static_cast<double>(start_ticks) / static_cast<double>(::sysconf(_SC_CLK_TCK));
  const auto started =
      fs::file_time_type::clock::now() - std::chrono::duration_cast<fs::file_time_type::duration>(
                                             std::chrono::duration<double>(age_s));
  // Started after the temporary was made (with a second's slack): another process.
  return started <= made + std::chrono::seconds(1);
}

}  // namespace

std::pair<std::uintmax_t, std::uint32_t> file_size_and_crc32(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read '" + file.string() + "'");
  boost::crc_32_type crc;
  std::array<char, 65536> buf{};
  std::uintmax_t n = 0;
  while (in) {
    in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
    const auto got = static_cast<std::size_t>(in.gcount());
    crc.process_bytes(buf.data(), got);
    n += got;
  }
  if (in.bad()) throw std::runtime_error("cannot read '" + file.string() + "'");
  return {n, crc.checksum()};
}

long temporary_owner_pid(const std::string& name) {
  if (name.size() < 2 || name[0] != '.') return -1;
  auto digits = [](const std::string& s) {
    return !s.empty() && s.size() < 12 &&
           std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
  };
  if (const auto p = name.rfind(kPartial); p != std::string::npos && p > 1) {
    const std::string pid = name.substr(p + std::strlen(kPartial));
    if (digits(pid)) return std::stol(pid);
  }
  if (const auto t = name.rfind(".tmp."); t != std::string::npos && t > 1) {
    const std::string tail = name.substr(t + 5);
    const auto dot = tail.find('.');
    if (dot == std::string::npos) return tail.size() == 6 ? 0 : -1;  // legacy mkstemp name
    if (digits(tail.substr(0, dot)) && tail.size() - dot - 1 == 6)
      return std::stol(tail.substr(0, dot));
  }
  return -1;
}

std::vector<fs::path> remove_stale_temporaries(const fs::path& dir, bool legacy_too) {
  std::vector<fs::path> removed;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return removed;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const long pid = temporary_owner_pid(e.path().filename().string());
    if (pid < 0 || (pid == 0 && !legacy_too)) continue;
    std::error_code ec2;
    const auto made = fs::last_write_time(e.path(), ec2);
    if (ec2 || (pid > 0 && pid_alive_since(pid, made))) continue;
    if (fs::remove_all(e.path(), ec2) > 0 && !ec2) removed.push_back(e.path());
  }
  if (!removed.empty()) fsync_dir(dir);
  return removed;
}

std::string describe_swept(const std::vector<fs::path>& removed) {
  if (removed.empty()) return {};
  std::string names;
  for (const auto& p : removed)
    names += (names.empty() ? "" : ", ") + p.string();
  return "removed " + std::to_string(removed.size()) +
         (removed.size() == 1 ? " temporary" : " temporaries") +
         " left by an interrupted errsep run: " + names;
}

std::string sweep_beside(const std::vector<fs::path>& files) {
  std::set<fs::path> dirs;
  std::vector<fs::path> removed;
  for (const auto& f : files) {
    if (f.empty()) continue;
    const fs::path d = f.has_parent_path() ? f.parent_path() : fs::path(".");
    if (!dirs.insert(d.lexically_normal()).second) continue;
    for (auto& p : remove_stale_temporaries(d))
      removed.push_back(std::move(p));
  }
  return describe_swept(removed);
}

StagedDirectory::StagedDirectory(const fs::path& out, const std::string& kind)
    : StagedDirectory(out, StageOptions{kind, {}, false, {}}) {}

StagedDirectory::StagedDirectory(const fs::path& out, StageOptions opts)
    : out_(fs::absolute(out).lexically_normal()), opts_(std::move(opts)) {
  // Absolute: "--out ." names the current folder, whose staging folder goes beside it.
  if (!out_.has_filename()) out_ = out_.parent_path();
  if (opts_.kind.empty() || opts_.kind.find('/') != std::string::npos)
    throw std::invalid_argument("result set: kind '" + opts_.kind + "' must be a plain name");
  fs::path parent = out_.parent_path();
  if (parent.empty()) parent = ".";
  fs::create_directories(parent);
  swept_ = remove_stale_temporaries(parent);
  for (auto& p : remove_stale_temporaries(out_))
    swept_.push_back(std::move(p));
  run_id_ = make_run_id();

  const std::string where = "'" + out_.string() + "'";
  std::error_code ec;
  const bool exists = fs::exists(out_, ec);
  if (exists && !fs::is_directory(out_))
    throw std::runtime_error(where + " exists and is not a folder: choose another output folder");
  const bool has_manifest = exists && fs::exists(out_ / kManifestName);
  if (opts_.extend) {
    // The set stays the run's that wrote its data (kind, run id, writer); this run is recorded
    // as one that added files to it.
    if (!exists) throw std::runtime_error(where + ": no such result folder");
    const std::string me = run_id_ + " " + utc_stamp("%Y-%m-%dT%H:%M:%SZ") + " " +
                           (opts_.writer.empty() ? std::string("errsep") : opts_.writer);
    if (has_manifest) {
      require_whole_result_set(out_);
      std::string why;
      const Manifest m = read_manifest(out_, &why);
      base_ = std::make_unique<ExtendedFrom>(
          ExtendedFrom{m.kind, m.run_id, m.writer, m.created_utc, m.extended});
      base_->extended.push_back(me);
    } else {
      base_ = std::make_unique<ExtendedFrom>(
          ExtendedFrom{opts_.kind,
                       run_id_,
                       opts_.writer,
                       utc_stamp("%Y-%m-%dT%H:%M:%SZ"),
                       {"adopted " + me + ": the files of a folder without a manifest, as found"}});
    }
  } else if (has_manifest) {
    std::string why;
    const Manifest m = read_manifest(out_, &why);
    if (m.kind != opts_.kind)
      throw std::runtime_error(
          where + " holds a result set of kind '" + (m.kind.empty() ? "?" : m.kind) + "' (run " +
          m.run_id + "), which this " + opts_.kind +
          " result would replace as a whole: choose another output folder (e.g. a sub-folder)");
  } else if (exists && !entries(out_).empty()) {
    throw std::runtime_error(
        where + " holds files that are not an errsep result set (no " + kManifestName +
        ": written by hand or by an older errsep); errsep replaces only a result set of its own "
        "kind: remove them or choose another output folder");
  }

  dir_ = parent / ("." + out_.filename().string() + "." + opts_.kind + kPartial +
                   std::to_string(::getpid()));
  fs::remove_all(dir_);
  fs::create_directory(dir_);
  if (opts_.extend) link_tree(out_, dir_, opts_.replace);
}

StagedDirectory::~StagedDirectory() {
  std::error_code ec;
  fs::remove_all(dir_, ec);  // after commit() the earlier set, else the partial one
}

std::vector<fs::path> StagedDirectory::commit() {
  if (committed_) throw std::logic_error("StagedDirectory::commit() called twice");
  Manifest m;
  m.kind = opts_.kind;
  m.run_id = run_id_;
  m.writer = opts_.writer.empty() ? std::string("errsep") : opts_.writer;
  m.created_utc = utc_stamp("%Y-%m-%dT%H:%M:%SZ");
  if (base_) {
    m.kind = base_->kind;
    m.run_id = base_->run_id;
    m.writer = base_->writer;
    m.created_utc = base_->created_utc;
    m.extended = base_->extended;
  }
  collect(dir_, dir_, m);
  write_file_atomic(dir_ / kManifestName, format_manifest(m));  // last; fsyncs dir_

  const fs::path parent = dir_.parent_path();
  std::error_code ec;
  if (!fs::exists(out_, ec)) {
    fs::rename(dir_, out_);
  } else if (::renameat2(AT_FDCWD, dir_.c_str(), AT_FDCWD, out_.c_str(), RENAME_EXCHANGE) != 0) {
    const int err = errno;
    if (err != EINVAL && err != ENOSYS && err != ENOTSUP)
      throw std::runtime_error("cannot move the result set into '" + out_.string() +
                               "': " + std::strerror(err));
    // No exchange on this file system: move the earlier set aside (a name the next run's sweep
    // knows), then the new one in.  A kill between the two leaves no set at the target.
    const fs::path aside = parent / ("." + out_.filename().string() + "." + opts_.kind + "-old" +
                                     kPartial + std::to_string(::getpid()));
    fs::rename(out_, aside);
    fs::rename(dir_, out_);
    fs::rename(aside, dir_);  // removed below, as after an exchange
  }
  committed_ = true;
  fsync_dir(parent);
  fs::remove_all(dir_, ec);  // the earlier set
  std::vector<fs::path> files;
  for (const auto& f : m.files)
    files.push_back(out_ / f.path);
  for (const auto& s : m.sets)
    files.push_back(out_ / s.first);
  files.push_back(out_ / kManifestName);
  return files;
}

ResultSetCheck check_result_set(const fs::path& dir) {
  ResultSetCheck c;
  if (!fs::exists(dir / kManifestName)) return c;
  c.has_manifest = true;
  std::string why;
  const Manifest m = read_manifest(dir, &why);
  c.kind = m.kind;
  c.run_id = m.run_id;
  c.writer = m.writer;
  c.run_ids = {m.run_id};
  for (const auto& e : m.extended)
    if (e.rfind("adopted ", 0) != 0) c.run_ids.push_back(e.substr(0, e.find(' ')));
  if (!why.empty()) {
    c.problems.push_back(why);
    return c;
  }
  std::set<std::string> listed;
  char buf[160];
  for (const auto& f : m.files) {
    c.files.push_back(f.path);
    listed.insert(f.path);
    const fs::path p = dir / f.path;
    std::error_code ec;
    if (!fs::is_regular_file(p, ec)) {
      c.problems.push_back("missing " + f.path);
      continue;
    }
    try {
      const auto [bytes, crc] = file_size_and_crc32(p);
      if (bytes != f.bytes) {
        std::snprintf(buf, sizeof buf, ": %ju bytes, the manifest says %ju", bytes, f.bytes);
        c.problems.push_back(f.path + buf + " (cut short, or from another run)");
      } else if (crc != f.crc) {
        std::snprintf(buf, sizeof buf, ": CRC-32 %08x, the manifest says %08x", crc, f.crc);
        c.problems.push_back(f.path + buf + " (changed since the run, or from another run)");
      }
    } catch (const std::exception& e) {
      c.problems.push_back(f.path + ": " + e.what());
    }
  }
  for (const auto& [rel, id] : m.sets) {
    c.files.push_back(rel);
    listed.insert(rel.substr(0, rel.size() - 1));
    const ResultSetCheck sub = check_result_set(dir / rel);
    if (!sub.has_manifest) {
      c.problems.push_back("missing " + rel + " (a result set of its own)");
      continue;
    }
    for (const auto& p : sub.problems)
      c.problems.push_back(rel + p);
  }
  // Anything else in the folder was added after the run (the set's own files are all there and
  // unchanged, so it is whole; readers say that these are not part of it).
  std::vector<fs::path> todo = {dir};
  while (!todo.empty()) {
    const fs::path d = todo.back();
    todo.pop_back();
    for (const auto& e : entries(d)) {
      const std::string rel = e.path().lexically_relative(dir).generic_string();
      if (listed.count(rel) || (d == dir && rel == kManifestName)) continue;
      if (e.is_directory()) {
        const ResultSetCheck sub = check_result_set(e.path());
        if (sub.has_manifest) {
          // A set added later inside this one (errsep-refine --out DIR/refine): whole or not.
          for (const auto& p : sub.problems)
            c.problems.push_back(rel + "/" + p);
        } else {
          todo.push_back(e.path());
        }
        continue;
      }
      c.extra.push_back(rel);
    }
  }
  return c;
}

bool require_whole_result_set(const fs::path& dir) {
  const ResultSetCheck c = check_result_set(dir);
  if (!c.has_manifest) return false;
  if (c.problems.empty()) return true;
  std::string all;
  for (const auto& p : c.problems)
    all += (all.empty() ? "" : "; ") + p;
  throw std::runtime_error(dir.string() + "/: not a whole result set (run " + c.run_id + ", " +
                           c.writer + "): " + all);
}

void require_whole_set_of(const fs::path& file) {
  fs::path dir = file.parent_path();
  if (dir.empty()) dir = ".";
  if (fs::exists(dir / kManifestName)) require_whole_result_set(dir);
}

}  // namespace errsep::io

#include "caps/core/atomic_output.hpp"

#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <map>
#include <mutex>
#include <random>
#include <set>

#include "caps/core/error.hpp"
#include "caps/core/reporter.hpp"

namespace fs = std::filesystem;

namespace caps {
namespace {

std::string unique_suffix() {
  static thread_local std::mt19937_64 rng{std::random_device{}()};
  return cat(".tmp-", ::getpid(), "-", std::hex, rng() & 0xffffff);
}

fs::path parent_of(const fs::path& p) {
  fs::path parent = p.parent_path();
  return parent.empty() ? fs::path(".") : parent;
}

// What this process is writing: its claims (the lock file's descriptor, how many nested claims,
// --force) and its temporaries, so that an interrupted run can remove them from another thread.
struct Claim {
  int fd = -1;
  std::string lock_path;
  int count = 0;
  bool force = false;
};
struct Registry {
  std::mutex mutex;
  std::map<std::string, Claim> claims;  // by the output's absolute path
  std::set<std::string> temporaries;
  bool abandoned = false;
  pid_t pid = ::getpid();
};
Registry& registry() {
  static Registry* r = new Registry;  // never destroyed: used until _exit on an interruption
  if (r->pid != ::getpid()) {
    // A forked child holds none of its parent's claims (their locks stay the parent's).
    for (auto& [key, c] : r->claims) ::close(c.fd);
    r->claims.clear();
    r->temporaries.clear();
    r->pid = ::getpid();
  }
  return *r;
}

fs::path strip_separator(fs::path p) {
  if (p.filename().empty() && p.has_parent_path()) p = p.parent_path();  // "out/" -> "out"
  return p;
}

std::string key_of(const fs::path& p) {
  std::error_code ec;
  const fs::path abs = fs::absolute(strip_separator(p), ec);
  return (ec ? p : abs).lexically_normal().string();
}

// The claim of `path` if this process holds one (nullptr otherwise). Call with the mutex held.
const Claim* claim_of(const fs::path& path) {
  auto& claims = registry().claims;
  const auto it = claims.find(key_of(path));
  return it == claims.end() ? nullptr : &it->second;
}

void add_temporary(const fs::path& tmp) {
  std::lock_guard lock(registry().mutex);
  registry().temporaries.insert(tmp.string());
}
void drop_temporary(const fs::path& tmp) {
  std::lock_guard lock(registry().mutex);
  registry().temporaries.erase(tmp.string());
}

const char* kind_of(const struct stat& st) {
  if (S_ISLNK(st.st_mode)) return "a symbolic link";
  if (S_ISFIFO(st.st_mode)) return "a FIFO (named pipe)";
  if (S_ISCHR(st.st_mode)) return "a character device";
  if (S_ISBLK(st.st_mode)) return "a block device";
  if (S_ISSOCK(st.st_mode)) return "a socket";
  return "not a regular file";
}

// True if `dir` is a folder caps wrote: empty, or holding one of the files caps' outputs are
// known by (a model, a mesh, a result, a study, a registration, a render's images).
bool is_caps_folder(const fs::path& dir) {
  static const std::set<std::string> known = {
      "model.json", "summary.json", "mesh.json", "result.json", "comparison.json",
      "model_comparison.json", "registration.json", "sensitivity.json", "range.json",
      "report.html", "tissue.json"};
  std::error_code ec;
  bool empty = true;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    empty = false;
    const fs::path name = it->path().filename();
    if (known.count(name.string())) return true;
    const std::string ext = name.extension().string();
    if (ext == ".png" || ext == ".gif" || ext == ".glb") return true;  // caps render
  }
  return empty && !ec;
}

// Moves `from` to `to` without replacing anything at `to` (renameat2 RENAME_NOREPLACE; a file
// by link() and unlink() where the file system has no such rename). Throws InvalidInput if `to`
// exists.
void rename_no_replace(const fs::path& from, const fs::path& to) {
#ifdef RENAME_NOREPLACE
  if (::renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), RENAME_NOREPLACE) == 0) return;
  int err = errno;
#else
  int err = EINVAL;
#endif
  if (err == EINVAL || err == ENOSYS) {
    struct stat st {};
    if (::lstat(from.c_str(), &st) == 0 && !S_ISDIR(st.st_mode)) {
      if (::link(from.c_str(), to.c_str()) == 0) {
        ::unlink(from.c_str());
        return;
      }
      err = errno;
    } else {
      // A folder: rename() refuses a non-empty target folder and any file; an empty folder that
      // appeared meanwhile is the only one it would replace.
      std::error_code ec;
      if (!fs::exists(fs::symlink_status(to, ec))) {
        fs::rename(from, to, ec);
        if (!ec) return;
        err = ec.value();
      } else {
        err = EEXIST;
      }
    }
  }
  if (err == EEXIST || err == ENOTEMPTY)
    throw InvalidInput(cat(to.string(), ": appeared while this run was writing it (another "
                           "program made it); it was left as it is: choose another output or "
                           "pass --force to replace it"));
  throw IoError(cat(to.string(), ": cannot move the finished output into place: ",
                    std::strerror(err)));
}

// Moves a finished temporary into place: without replacing unless the output's claim (or, with
// no claim, the caller) allows it; refused once the run was abandoned.
void move_into_place(const fs::path& tmp, const fs::path& target, bool replace) {
  std::lock_guard lock(registry().mutex);
  if (registry().abandoned) throw Cancelled("interrupted");
  if (const Claim* c = claim_of(target)) replace = c->force;
  if (replace) {
    std::error_code ec;
    fs::rename(tmp, target, ec);
    if (ec) throw IoError(cat(target.string(), ": cannot move the finished output into place: ",
                              ec.message()));
  } else {
    rename_no_replace(tmp, target);
  }
  registry().temporaries.erase(tmp.string());
}

void require_writable_dir(const fs::path& dir, const fs::path& target) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw IoError(cat(target.string(), ": cannot write here, the folder ", dir.string(),
                      " does not exist; create it first or choose another output path"));
  if (::access(dir.c_str(), W_OK) != 0)
    throw IoError(cat(target.string(), ": cannot write here, the folder ", dir.string(),
                      " is not writable; choose another output path"));
}

// Removes the temporaries that an earlier run writing `target` left behind when it was killed
// (`<name>.tmp-<pid>-<hex>`, and `.old` ones of a replacement): those whose process no longer
// exists. Another live run's temporaries are left alone.
void remove_stale_temporaries(const fs::path& dir, const fs::path& target) {
  const std::string prefix = target.filename().string() + ".tmp-";
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.compare(0, prefix.size(), prefix) != 0) continue;
    std::size_t at = prefix.size();
    long long pid = 0;
    while (at < name.size() && name[at] >= '0' && name[at] <= '9' && pid < (1LL << 40))
      pid = pid * 10 + (name[at++] - '0');
    if (at == prefix.size() || at >= name.size() || name[at] != '-' || pid <= 0 ||
        pid > (1LL << 31) || pid == ::getpid())
      continue;
    if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;  // still running
    std::error_code rm;
    fs::remove_all(it->path(), rm);
  }
}

}  // namespace

void write_file_atomic(const fs::path& path, const std::function<void(const fs::path&)>& write) {
  const fs::path dir = parent_of(path);
  require_writable_dir(dir, path);
  {
    std::lock_guard lock(registry().mutex);
    const Claim* c = claim_of(path);
    // Rewriting a file in place (a model's model.json) replaces a regular file only; an output
    // claimed with --force, also only a regular file (check_replaceable).
    if (c) check_replaceable(path, c->force);
    struct stat st {};
    if (!c && ::lstat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode) && !S_ISLNK(st.st_mode))
      throw InvalidInput(cat(path.string(), ": is ", S_ISDIR(st.st_mode) ? "a folder" : kind_of(st),
                             ", not a file caps can replace; choose another output"));
  }
  remove_stale_temporaries(dir, path);
  const fs::path tmp = dir / (path.filename().string() + unique_suffix());
  add_temporary(tmp);
  try {
    write(tmp);
    move_into_place(tmp, path, true);
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    drop_temporary(tmp);
    throw;
  }
}

void write_text_atomic(const fs::path& path, const std::string& text) {
  write_file_atomic(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out << text;
    out.close();
    if (!out) throw IoError(cat(path.string(), ": write failed (disk full?)"));
  });
}

void check_replaceable(const fs::path& path, bool force) {
  const fs::path p = strip_separator(path);
  struct stat st {};
  if (::lstat(p.c_str(), &st) != 0) return;  // nothing there
  if (!force)
    throw InvalidInput(cat(p.string(), ": output already exists; choose another name or pass "
                           "--force to replace it"));
  if (S_ISREG(st.st_mode)) return;
  if (S_ISDIR(st.st_mode)) {
    if (is_caps_folder(p)) return;
    throw InvalidInput(cat(p.string(), ": is a folder caps did not write (none of caps' outputs "
                           "in it, such as model.json or summary.json); --force replaces only "
                           "caps' own outputs: remove it yourself or choose another output"));
  }
  throw InvalidInput(cat(p.string(), ": is ", kind_of(st), "; --force replaces only a regular "
                         "file or a folder caps wrote, never ", kind_of(st),
                         S_ISLNK(st.st_mode) ? " or what it points to" : "",
                         ": choose another output"));
}

OutputClaim::OutputClaim(const fs::path& path, bool force) {
  const fs::path target = strip_separator(path);
  if (target.empty()) return;
  const std::string key = key_of(target);
  const fs::path dir = parent_of(target);
  std::error_code ec;
  if (!fs::is_directory(dir, ec) || ::access(dir.c_str(), W_OK) != 0) return;
  check_replaceable(target, force);
  std::lock_guard lock(registry().mutex);
  auto& claims = registry().claims;
  if (auto it = claims.find(key); it != claims.end()) {
    ++it->second.count;
    key_ = key;
    return;
  }
  Claim c;
  c.lock_path = (dir / (target.filename().string() + ".caps-claim")).string();
  c.force = force;
  for (int attempt = 0; attempt < 8; ++attempt) {
    const int fd = ::open(c.lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0644);
    if (fd < 0)
      throw IoError(cat(target.string(), ": cannot claim the output (", c.lock_path, ": ",
                        std::strerror(errno), ")"));
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      char pid[32] = {};
      const ssize_t n = ::pread(fd, pid, sizeof pid - 1, 0);
      ::close(fd);
      std::string holder = n > 0 ? std::string(pid, static_cast<std::size_t>(n)) : "";
      while (!holder.empty() && (holder.back() == '\n' || holder.back() == ' ')) holder.pop_back();
      throw InvalidInput(cat(target.string(), ": another caps run",
                             holder.empty() ? std::string() : cat(" (process ", holder, ")"),
                             " is writing this output now; wait for it to finish or choose "
                             "another output"));
    }
    // The lock file may have been removed by its last holder between open() and flock(): then
    // the lock is on a file no other run can see; open the name again.
    struct stat held {}, named {};
    if (::fstat(fd, &held) == 0 && ::stat(c.lock_path.c_str(), &named) == 0 &&
        held.st_ino == named.st_ino && held.st_dev == named.st_dev) {
      const std::string pid = cat(::getpid(), "\n");
      if (::ftruncate(fd, 0) == 0) [[maybe_unused]] const ssize_t n = ::pwrite(fd, pid.data(), pid.size(), 0);
      c.fd = fd;
      c.count = 1;
      claims.emplace(key, c);
      key_ = key;
      return;
    }
    ::close(fd);
  }
  throw IoError(cat(target.string(), ": cannot claim the output (", c.lock_path,
                    " keeps changing)"));
}

OutputClaim::~OutputClaim() {
  if (key_.empty()) return;
  std::lock_guard lock(registry().mutex);
  auto& claims = registry().claims;
  const auto it = claims.find(key_);
  if (it == claims.end() || --it->second.count > 0) return;
  ::unlink(it->second.lock_path.c_str());  // while still locked: no one else holds this file
  ::close(it->second.fd);
  claims.erase(it);
}

std::vector<std::string> abandon_unfinished_outputs() {
  std::lock_guard lock(registry().mutex);
  Registry& r = registry();
  r.abandoned = true;
  std::vector<std::string> outputs;
  for (const std::string& tmp : r.temporaries) {
    // The writing thread may still add files to a folder being removed: try again.
    for (int attempt = 0; attempt < 5; ++attempt) {
      std::error_code ec;
      fs::remove_all(tmp, ec);
      if (!fs::exists(fs::symlink_status(tmp, ec))) break;
    }
  }
  r.temporaries.clear();
  for (auto& [key, c] : r.claims) {
    outputs.push_back(key);
    ::unlink(c.lock_path.c_str());
  }
  return outputs;
}

OutputDirectory::OutputDirectory(fs::path final_path, bool force)
    : final_(strip_separator(std::move(final_path))), force_(force), claim_(final_, force) {
  std::error_code ec;
  if (fs::exists(fs::symlink_status(final_, ec)) && !force_)
    throw InvalidInput(cat(final_.string(), ": output already exists; choose another name or "
                           "pass --force to replace it"));
  if (fs::exists(final_, ec) && !fs::is_directory(fs::symlink_status(final_, ec)))
    throw InvalidInput(cat(final_.string(), ": exists and is not a directory; choose another "
                           "output path"));
  const fs::path dir = parent_of(final_);
  require_writable_dir(dir, final_);
  check_replaceable(final_, force_);
  remove_stale_temporaries(dir, final_);
  tmp_ = dir / (final_.filename().string() + unique_suffix());
  add_temporary(tmp_);
  if (!fs::create_directory(tmp_, ec) || ec) {
    drop_temporary(tmp_);
    throw IoError(cat(final_.string(), ": cannot create a folder in ", dir.string(), ": ",
                      ec.message()));
  }
}

OutputDirectory::~OutputDirectory() {
  if (!committed_) {
    std::error_code ec;
    fs::remove_all(tmp_, ec);
    drop_temporary(tmp_);
  }
}

void OutputDirectory::commit() {
  std::error_code ec;
  if (!force_) {
    move_into_place(tmp_, final_, false);
    committed_ = true;
    return;
  }
  check_replaceable(final_, true);  // what is there now, not what was there at the start
  fs::path old;
  if (fs::exists(fs::symlink_status(final_, ec))) {
    old = final_.string() + unique_suffix() + ".old";
    fs::rename(final_, old, ec);
    if (ec) throw IoError(cat(final_.string(), ": cannot replace the existing output: ",
                              ec.message()));
  }
  try {
    move_into_place(tmp_, final_, false);
  } catch (...) {
    if (!old.empty()) fs::rename(old, final_, ec);
    throw;
  }
  committed_ = true;
  if (!old.empty()) fs::remove_all(old, ec);
}

}  // namespace caps

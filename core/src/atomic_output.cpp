#include "caps/core/atomic_output.hpp"

#include <signal.h>
#include <unistd.h>

#include <cerrno>

#include <fstream>
#include <random>

#include "caps/core/error.hpp"

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
  remove_stale_temporaries(dir, path);
  const fs::path tmp = dir / (path.filename().string() + unique_suffix());
  try {
    write(tmp);
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) throw IoError(cat(path.string(), ": cannot move the finished file into place: ",
                              ec.message()));
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
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

OutputDirectory::OutputDirectory(fs::path final_path, bool force)
    : final_(std::move(final_path)), force_(force) {
  std::error_code ec;
  if (final_.filename().empty()) final_ = final_.parent_path();  // "out/" -> "out"
  if (fs::exists(final_, ec) && !force_)
    throw InvalidInput(cat(final_.string(), ": output already exists; choose another name or "
                           "pass --force to replace it"));
  if (fs::exists(final_, ec) && !fs::is_directory(final_, ec))
    throw InvalidInput(cat(final_.string(), ": exists and is not a directory; choose another "
                           "output path"));
  const fs::path dir = parent_of(final_);
  require_writable_dir(dir, final_);
  remove_stale_temporaries(dir, final_);
  tmp_ = dir / (final_.filename().string() + unique_suffix());
  if (!fs::create_directory(tmp_, ec) || ec)
    throw IoError(cat(final_.string(), ": cannot create a folder in ", dir.string(), ": ",
                      ec.message()));
}

OutputDirectory::~OutputDirectory() {
  if (!committed_) {
    std::error_code ec;
    fs::remove_all(tmp_, ec);
  }
}

void OutputDirectory::commit() {
  std::error_code ec;
  fs::path old;
  if (fs::exists(final_, ec)) {
    old = final_.string() + unique_suffix() + ".old";
    fs::rename(final_, old, ec);
    if (ec) throw IoError(cat(final_.string(), ": cannot replace the existing output: ",
                              ec.message()));
  }
  fs::rename(tmp_, final_, ec);
  if (ec) {
    if (!old.empty()) fs::rename(old, final_);
    throw IoError(cat(final_.string(), ": cannot move the finished output into place: ",
                      ec.message()));
  }
  committed_ = true;
  if (!old.empty()) fs::remove_all(old, ec);
}

}  // namespace caps

#include "caps/core/atomic_output.hpp"

#include <unistd.h>

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

}  // namespace

void write_file_atomic(const fs::path& path, const std::function<void(const fs::path&)>& write) {
  const fs::path dir = parent_of(path);
  require_writable_dir(dir, path);
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

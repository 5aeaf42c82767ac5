#pragma once
/// @brief Atomic outputs: write under a temporary name, then rename into place.
///
/// A failed run leaves neither a partial file nor a clobbered old one. A run that was killed
/// leaves its temporary (`<name>.tmp-<pid>-<hex>`); the next run writing `<name>` removes those
/// whose process no longer exists.
///
/// An output is claimed while a run writes it (OutputClaim: `<name>.caps-claim` beside it, held
/// with an exclusive lock the system drops when the process ends): a second run writing the same
/// output is refused, and without --force the finished output is moved into place only if nothing
/// took its name meanwhile (a rename that does not replace). --force replaces only a regular file
/// or a folder caps wrote, never a device, a FIFO, a socket or a symbolic link.

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace caps {

/// Writes a file atomically: `write` receives a temporary path in the same directory and must
/// create the file there; on success it is renamed to `path`. On any exception the temporary
/// file is removed and the exception propagates. Throws IoError if the directory is not writable.
void write_file_atomic(const std::filesystem::path& path,
                       const std::function<void(const std::filesystem::path& tmp)>& write);

/// Writes text to a file atomically.
void write_text_atomic(const std::filesystem::path& path, const std::string& text);

/// Throws InvalidInput unless `path` may be written: it does not exist, or `force` is set and it
/// is a regular file or a folder caps wrote (one holding a file of caps' outputs: model.json,
/// summary.json, mesh.json, result.json, ...; or empty). Symbolic links are not followed.
void check_replaceable(const std::filesystem::path& path, bool force);

/// This process's claim on an output (a file or folder) for as long as the object lives: refused
/// (InvalidInput naming the other process) while another process holds it; claims of the same
/// path within this process nest. Checks check_replaceable(path, force) when it exists; the
/// atomic writes above then move a finished output of a claim without `force` into place only if
/// the name is still free. Without an existing writable parent folder nothing is claimed (the
/// writer reports the folder).
class OutputClaim {
 public:
  OutputClaim(const std::filesystem::path& path, bool force);
  ~OutputClaim();
  OutputClaim(const OutputClaim&) = delete;
  OutputClaim& operator=(const OutputClaim&) = delete;

 private:
  std::string key_;  ///< empty: nothing claimed
};

/// For a run that is being interrupted (SIGINT, SIGTERM), from any thread: removes this
/// process's temporaries and claims, and makes every later move into place fail. Returns the
/// outputs that were being written (left unwritten).
std::vector<std::string> abandon_unfinished_outputs();

/// An output directory built under a temporary sibling name and renamed into place by commit().
/// If the object is destroyed without commit(), the temporary directory is removed.
class OutputDirectory {
 public:
  /// Checks that `final_path` can be created: it must not exist unless `force` is set (then it
  /// is replaced at commit) and its parent must be writable. Throws InvalidInput or IoError.
  OutputDirectory(std::filesystem::path final_path, bool force);
  ~OutputDirectory();
  OutputDirectory(const OutputDirectory&) = delete;
  OutputDirectory& operator=(const OutputDirectory&) = delete;

  /// The temporary directory to write into.
  const std::filesystem::path& path() const { return tmp_; }
  /// Moves the finished directory into place.
  void commit();

 private:
  std::filesystem::path final_;
  std::filesystem::path tmp_;
  bool force_;
  bool committed_ = false;
  OutputClaim claim_;
};

}  // namespace caps

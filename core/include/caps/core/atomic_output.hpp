#pragma once
/// @brief Atomic outputs: write under a temporary name, then rename into place.
///
/// A failed run leaves neither a partial file nor a clobbered old one. A run that was killed
/// leaves its temporary (`<name>.tmp-<pid>-<hex>`); the next run writing `<name>` removes those
/// whose process no longer exists.

#include <filesystem>
#include <functional>
#include <string>

namespace caps {

/// Writes a file atomically: `write` receives a temporary path in the same directory and must
/// create the file there; on success it is renamed to `path`. On any exception the temporary
/// file is removed and the exception propagates. Throws IoError if the directory is not writable.
void write_file_atomic(const std::filesystem::path& path,
                       const std::function<void(const std::filesystem::path& tmp)>& write);

/// Writes text to a file atomically.
void write_text_atomic(const std::filesystem::path& path, const std::string& text);

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
};

}  // namespace caps

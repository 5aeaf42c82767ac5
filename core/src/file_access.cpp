#include "caps/core/file_access.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "caps/core/error.hpp"

namespace caps {

std::string unreadable_reason(const std::filesystem::path& path, bool folder) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | (folder ? O_DIRECTORY : 0));
  if (fd < 0) {
    const int e = errno;
    switch (e) {
      case ENOENT: return "no such file or folder";
      case EACCES:
      case EPERM: return "permission denied";
      case ELOOP: return "a symbolic link loop (a link that leads back to itself)";
      case ENOTDIR: return folder ? "not a folder" : "no such file or folder";
      case ENAMETOOLONG: return "the name is too long";
      default: return std::strerror(e);
    }
  }
  struct stat st {};
  const bool ok = ::fstat(fd, &st) == 0;
  ::close(fd);
  if (!ok) return std::strerror(errno);
  if (!folder && S_ISDIR(st.st_mode)) return "a folder, not a file";
  return {};
}

void require_readable(const std::filesystem::path& path, bool folder, const std::string& what_to_do) {
  const std::string why = unreadable_reason(path, folder);
  if (!why.empty()) throw IoError(cat(path.string(), ": ", why, "; ", what_to_do));
}

}  // namespace caps

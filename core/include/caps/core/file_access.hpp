#pragma once
/// @brief Why a file or folder cannot be read, in words a user can act on: the true cause
/// (permission denied, a symbolic link loop, a folder where a file is expected) rather than the
/// symptom a reader would report next (a damaged header, a missing file).

#include <filesystem>
#include <string>

namespace caps {

/// Why `path` cannot be opened for reading as a file (`folder` false) or a folder (`folder`
/// true): "no such file or folder", "permission denied", "a symbolic link loop", "a folder, not
/// a file", "not a folder", or the system's words; empty when it can be read.
std::string unreadable_reason(const std::filesystem::path& path, bool folder = false);

/// Throws IoError "<path>: <reason>; <what_to_do>" when unreadable_reason() is not empty.
void require_readable(const std::filesystem::path& path, bool folder, const std::string& what_to_do);

}  // namespace caps

#pragma once
// What every fuzz target shares: the input written as files into a private temporary folder (the
// readers take paths), split into the parts a format keeps in several files, and the rule of the
// targets: a caps::Error is an answer; anything else escaping (another exception, a crash, a
// sanitizer report, a hang, an allocation above libFuzzer's -malloc_limit_mb) is a finding.

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

#include "caps/core/error.hpp"

namespace caps_fuzz {

namespace fs = std::filesystem;

/// Separates the files of one input ("header\n--caps--\ndata"): a .nhdr and its data file, a
/// sidecar and its image, mesh.json and mesh.vtu.
inline constexpr std::string_view kSeparator = "\n--caps--\n";

/// The input's parts, at most `max_parts` (the last part keeps any further separators).
inline std::vector<std::string_view> split(const std::uint8_t* data, std::size_t size,
                                           std::size_t max_parts = 2) {
  std::string_view rest(reinterpret_cast<const char*>(data), size);
  std::vector<std::string_view> parts;
  while (parts.size() + 1 < max_parts) {
    const auto at = rest.find(kSeparator);
    if (at == std::string_view::npos) break;
    parts.push_back(rest.substr(0, at));
    rest.remove_prefix(at + kSeparator.size());
  }
  parts.push_back(rest);
  return parts;
}

/// This process's folder for input files (under TMPDIR), emptied for each input and removed at
/// exit.
inline const fs::path& work_dir() {
  static const fs::path dir = [] {
    const fs::path d = fs::temp_directory_path() / ("caps_fuzz_" + std::to_string(::getpid()));
    fs::remove_all(d);
    fs::create_directories(d);
    std::atexit([] { std::error_code ec; fs::remove_all(work_dir(), ec); });
    return d;
  }();
  return dir;
}

/// Empties the work folder (a previous input's files must not be read with this one).
inline const fs::path& fresh_dir() {
  const fs::path& d = work_dir();
  for (const auto& e : fs::directory_iterator(d)) fs::remove_all(e.path());
  return d;
}

/// Writes `bytes` to `name` in the work folder; returns its path.
inline fs::path put(const std::string& name, std::string_view bytes) {
  const fs::path p = work_dir() / name;
  std::ofstream(p, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return p;
}

/// Empties the work folder and writes the input's parts (split()) as the files `names`, as many
/// as there are parts; returns the folder.
inline const fs::path& put_parts(const std::uint8_t* data, std::size_t size,
                                 const std::vector<std::string>& names) {
  const auto parts = split(data, size, names.size());
  const fs::path& dir = fresh_dir();
  for (std::size_t i = 0; i < parts.size(); ++i) put(names[i], parts[i]);
  return dir;
}

/// Runs `f`, swallowing caps errors (a refusal is the right answer to a hostile input).
template <class F>
int answer(F&& f) {
  try {
    f();
  } catch (const caps::Error&) {
  }
  return 0;
}

}  // namespace caps_fuzz

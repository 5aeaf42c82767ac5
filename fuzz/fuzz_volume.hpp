#pragma once
// The volume readers' fuzz targets: read_volume() under a small budget, so that an allocation
// beyond the budget shows as a finding (libFuzzer's -malloc_limit_mb) instead of passing unseen.

#include "caps/volume/read_volume.hpp"
#include "fuzz_input.hpp"

namespace caps_fuzz {

/// 2^22 voxels, 64 MiB: what the fuzz targets allow a reader (scripts/fuzz.sh sets
/// -malloc_limit_mb above it).
inline caps::ReadOptions small_budget() {
  caps::ReadOptions o;
  o.max_voxels = 4194304.0;
  o.max_bytes = 67108864.0;
  return o;
}

/// Reads `path` under the small budget; caps errors are answers.
inline int read_volume_answer(const fs::path& path) {
  return answer([&] { (void)caps::read_volume(path, small_budget()); });
}

/// A format kept in one file (`attached`, e.g. in.nrrd) or, when the input has two parts, in a
/// header (`detached`, e.g. in.nhdr) naming its data file data.raw (the second part).
inline int read_attached_or_detached(const std::uint8_t* data, std::size_t size,
                                     const std::string& attached, const std::string& detached) {
  const auto parts = split(data, size);
  fresh_dir();
  if (parts.size() == 1) return read_volume_answer(put(attached, parts[0]));
  put("data.raw", parts[1]);
  return read_volume_answer(put(detached, parts[0]));
}

}  // namespace caps_fuzz

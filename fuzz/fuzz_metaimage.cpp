// MetaImage: one .mha, or (two parts) in.mhd and its data file data.raw.
#include "fuzz_volume.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace caps_fuzz;
  const auto parts = split(data, size);
  fresh_dir();
  if (parts.size() == 1) return read_volume_answer(put("in.mha", parts[0]));
  put("data.raw", parts[1]);
  return read_volume_answer(put("in.mhd", parts[0]));
}

// MetaImage: one .mha, or (two parts) in.mhd and its data file data.raw.
#include "fuzz_volume.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return caps_fuzz::read_attached_or_detached(data, size, "in.mha", "in.mhd");
}

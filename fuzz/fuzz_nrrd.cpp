// NRRD: one attached .nrrd, or (two parts) a detached header in.nhdr and its data file data.raw.
#include "fuzz_volume.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return caps_fuzz::read_attached_or_detached(data, size, "in.nrrd", "in.nhdr");
}

// NIfTI-1/2: .nii, or .nii.gz when the input starts with the gzip magic.
#include "fuzz_volume.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace caps_fuzz;
  fresh_dir();
  const bool gz = size >= 2 && data[0] == 0x1f && data[1] == 0x8b;
  return read_volume_answer(
      put(gz ? "in.nii.gz" : "in.nii", {reinterpret_cast<const char*>(data), size}));
}

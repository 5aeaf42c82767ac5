// InVesalius .inv3: a gzip tar archive of a plist and a raw volume, through libarchive.
#include "fuzz_volume.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace caps_fuzz;
  fresh_dir();
  return read_volume_answer(put("in.inv3", {reinterpret_cast<const char*>(data), size}));
}

// DICOM through GDCM: a folder of one or two files (the input's parts), read as a series.
#include "fuzz_volume.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace caps_fuzz;
  const fs::path& dir = put_parts(data, size, {"01.dcm", "02.dcm"});
  return read_volume_answer(fs::exists(dir / "02.dcm") ? dir : dir / "01.dcm");
}

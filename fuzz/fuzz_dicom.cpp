// DICOM through GDCM: a folder of one or two files (the input's parts), read as a series.
#include "fuzz_volume.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace caps_fuzz;
  const auto parts = split(data, size);
  const fs::path& dir = fresh_dir();
  put("01.dcm", parts[0]);
  if (parts.size() > 1) put("02.dcm", parts[1]);
  return read_volume_answer(parts.size() > 1 ? dir : dir / "01.dcm");
}

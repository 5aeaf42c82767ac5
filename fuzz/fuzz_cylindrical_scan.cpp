// Cyberware-style cylindrical range image: the sidecar range.json and (second part) the range
// image range.png it names, read and reconstructed as a mesh.
#include "caps/surface/cylindrical_scan.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace caps_fuzz;
  const auto parts = split(data, size);
  fresh_dir();
  if (parts.size() > 1) put("range.png", parts[1]);
  const fs::path sidecar = put("range.json", parts[0]);
  return answer([&] { (void)caps::cylindrical_scan_mesh(caps::read_cylindrical_sidecar(sidecar)); });
}

// Cyberware-style cylindrical range image: the sidecar range.json and (second part) the range
// image range.png it names, read and reconstructed as a mesh.
#include "caps/surface/cylindrical_scan.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace caps_fuzz;
  const fs::path sidecar = put_parts(data, size, {"range.json", "range.png"}) / "range.json";
  return answer([&] { (void)caps::cylindrical_scan_mesh(caps::read_cylindrical_sidecar(sidecar)); });
}

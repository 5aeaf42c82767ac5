// glTF 2.0 through tinygltf: .glb when the input starts with the "glTF" magic, else .gltf.
#include "caps/surface/scan_io.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace caps_fuzz;
  fresh_dir();
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  const fs::path p = put(bytes.substr(0, 4) == "glTF" ? "in.glb" : "in.gltf", bytes);
  return answer([&] { (void)caps::read_scan_mesh(p); });
}

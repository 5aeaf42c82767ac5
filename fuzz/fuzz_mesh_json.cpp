// A mesh directory: mesh.json and (second part) mesh.vtu, read and validated by read_mesh_dir().
#include "caps/fem/mesh_io.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace caps_fuzz;
  const fs::path& dir = put_parts(data, size, {"mesh.json", "mesh.vtu"});
  return answer([&] { (void)caps::fem::read_mesh_dir(dir); });
}

// A mesh directory: mesh.json and (second part) mesh.vtu, read and validated by read_mesh_dir().
#include "caps/fem/mesh_io.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace caps_fuzz;
  const auto parts = split(data, size);
  const fs::path& dir = fresh_dir();
  put("mesh.json", parts[0]);
  if (parts.size() > 1) put("mesh.vtu", parts[1]);
  return answer([&] { (void)caps::fem::read_mesh_dir(dir); });
}

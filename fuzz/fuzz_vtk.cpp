// The .vtk scan reader (read_scan_mesh).
#include "caps/surface/scan_io.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace caps_fuzz;
  fresh_dir();
  const fs::path p = put("in.vtk", {reinterpret_cast<const char*>(data), size});
  return answer([&] { (void)caps::read_scan_mesh(p); });
}

// model.json of a model directory (read_model_info): its schema checks. The files it names do
// not exist, so a model.json that passes every field check ends in the missing-file refusal.
#include "caps/volume/model_dir.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace caps_fuzz;
  const fs::path& dir = fresh_dir();
  put("model.json", {reinterpret_cast<const char*>(data), size});
  return answer([&] { (void)caps::read_model_info(dir); });
}

// Plan files: parse_plan_json(), then the structural and geometric check of `caps plan check`
// (crossing cuts, excision borders, sutures), then the plan written and read again.
#include "caps/plan/check.hpp"
#include "caps/plan/plan_io.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace caps_fuzz;
  const std::string text(reinterpret_cast<const char*>(data), size);
  return answer([&] {
    const caps::plan::Plan plan = caps::plan::parse_plan_json(text, "fuzz.json");
    const std::string again = caps::plan::plan_to_json(plan);
    (void)caps::plan::parse_plan_json(again, "fuzz.json (written again)");
    (void)caps::plan::check_plan_structure(plan);
  });
}

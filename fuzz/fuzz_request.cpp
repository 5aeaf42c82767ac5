// The requests of the planner's HTTP API and of `--json` (app::read_request, which the server
// calls on each body): the first byte picks the request type, the rest is the JSON text; a
// request read is written and read again.
#include "caps/app/fields.hpp"
#include "caps/app/model.hpp"
#include "caps/app/plan.hpp"
#include "caps/app/render.hpp"
#include "caps/app/simulation.hpp"
#include "fuzz_input.hpp"

namespace {

template <class Request>
void round_trip(const std::string& text) {
  const auto request = caps::app::read_request<Request>(text, "fuzz request");
  (void)caps::app::read_request<Request>(caps::app::write_request(request), "written again");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace caps::app;
  if (size == 0) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  return caps_fuzz::answer([&] {
    switch (data[0] % 8) {
      case 0: return round_trip<PlanNewRequest>(text);
      case 1: return round_trip<PlanCheckRequest>(text);
      case 2: return round_trip<SimulateRequest>(text);
      case 3: return round_trip<MeshRequest>(text);
      case 4: return round_trip<FromScanRequest>(text);
      case 5: return round_trip<FromVolumeRequest>(text);
      case 6: return round_trip<RenderRequest>(text);
      default: return round_trip<PlanShowRequest>(text);
    }
  });
}

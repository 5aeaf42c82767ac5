// caps plan suggest (app/suggest.hpp) for a 10 mm lesion with 2 mm margins at the three places
// issue 39 names, on the demo's model with the defaults a user gets (ellipses every 15 deg, a
// linear sweep at 4 mm, the best 2 closed again neo-Hookean at 2 mm in the whole face): the wall
// time from request to suggestions.json, with the sweep's and the closures' parts as counters.
//   scripts/demo.sh   (or build/tools/caps model from-volume .../Cranium.inv3 -o out/cranium)
//   CAPS_BENCH_MODEL=out/cranium build/bench/bench_app_suggest
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <unistd.h>

#include "caps/app/suggest.hpp"
#include "blas_context.hpp"

namespace {

std::string model_dir() {
  const char* m = std::getenv("CAPS_BENCH_MODEL");
  return m ? m : "out/cranium";
}

struct Place {
  const char* name;
  const char* at;
};
// Mid-forehead; the cheek below the left lateral canthus (Cranium's eye plans lie at 40,52);
// the right nasal sidewall (planned on a local chart facing it).
constexpr Place kPlaces[] = {{"MidForehead", "0,105"},
                             {"CheekBelowTheLateralCanthus", "30,35"},
                             {"NasalSidewall", "-8,45"}};

void BM_Suggest(benchmark::State& state) {
  const Place& p = kPlaces[state.range(0)];
  state.SetLabel(p.name);
  const std::filesystem::path out = std::filesystem::temp_directory_path() /
                                    ("caps_bench_suggest_" + std::to_string(::getpid()));
  caps::app::SuggestResult r;
  for (auto _ : state) {
    caps::app::SuggestRequest q;
    q.model = model_dir();
    q.at = p.at;
    q.diameter = 10;
    q.output = out.string();
    q.force = true;
    r = caps::app::run_plan_suggest(q);
  }
  std::filesystem::remove_all(out);
  int ranked = 0;
  for (const auto& d : r.designs) ranked += d.rank > 0;
  state.counters["sweep_s"] = r.sweep_s;
  state.counters["refine_s"] = r.refine_s;
  state.counters["ranked"] = ranked;
  state.counters["designs"] = static_cast<double>(r.designs.size());
}
BENCHMARK(BM_Suggest)->DenseRange(0, 2)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();

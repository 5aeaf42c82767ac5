// The whole-face tissue model of the demo patient (Cranium.inv3), stage by stage: the level sets
// of skin and bone (OpenVDB), the label image + CGAL Mesh_3 + layers + flags, and the whole
// build as `caps model tissue` runs it (level sets and model; reading the CT and segmenting it
// are bench_volume_model's). Counters: nodes, tets, peak memory. docs/benchmarks.md.
//   build/bench/bench_mesher_tissue --benchmark_counters_tabular=true
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <filesystem>

#include "caps/mesher/tissue_model.hpp"
#include "caps/volume/model.hpp"
#include "caps/volume/read_volume.hpp"

using namespace caps;

namespace {

const std::filesystem::path kCranium = "/usr/share/doc/invesalius-examples/examples/Cranium.inv3";

double peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

// The demo patient's model, built once (the segmentation and maps the tissue model needs).
const VolumeModel& cranium() {
  static const VolumeModel m = build_volume_model(read_volume(kCranium));
  return m;
}

void BM_LevelSets(benchmark::State& state) {
  const VolumeModel& m = cranium();
  for (auto _ : state) benchmark::DoNotOptimize(mesher::tissue_level_sets(m.segmentation));
  state.counters["peak_MB"] = peak_rss_mb();
}

void BM_MeshLayersFlags(benchmark::State& state) {
  const VolumeModel& m = cranium();
  const mesher::TissueLevelSets ls = mesher::tissue_level_sets(m.segmentation);
  mesher::TissueModel t;
  for (auto _ : state) t = mesher::build_tissue_model(m.segmentation, m.maps, m.stats, ls);
  state.counters["nodes"] = static_cast<double>(t.n_nodes());
  state.counters["tets"] = static_cast<double>(t.n_tets());
  state.counters["mesh_s"] = t.seconds_mesh;
  state.counters["peak_MB"] = peak_rss_mb();
}

void BM_WholeTissueModel(benchmark::State& state) {
  const VolumeModel& m = cranium();
  mesher::TissueModel t;
  for (auto _ : state) {
    const mesher::TissueLevelSets ls = mesher::tissue_level_sets(m.segmentation);
    t = mesher::build_tissue_model(m.segmentation, m.maps, m.stats, ls);
  }
  state.counters["nodes"] = static_cast<double>(t.n_nodes());
  state.counters["tets"] = static_cast<double>(t.n_tets());
  state.counters["peak_MB"] = peak_rss_mb();
}

}  // namespace

BENCHMARK(BM_LevelSets)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK(BM_MeshLayersFlags)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK(BM_WholeTissueModel)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK_MAIN();

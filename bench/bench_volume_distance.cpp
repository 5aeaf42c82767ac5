// Distances to the bone on the demo patient (Cranium.inv3): the exact Euclidean distance
// transform with its feature transform (what the ray caster uses for the normal thickness)
// against OpenVDB's narrow-band signed distance field of the bone surface, with a band as deep as
// the bone cap (the same question: the nearest bone within 40 mm) and a contact-style 3-voxel band.
//   build/bench/bench_volume_distance --benchmark_counters_tabular=true
#include <benchmark/benchmark.h>

#include "caps/volume/distance_field.hpp"
#include "caps/volume/model.hpp"
#include "caps/volume/morphology.hpp"
#include "caps/volume/read_volume.hpp"

using namespace caps;

namespace {

const VolumeModel& cranium() {
  static const VolumeModel m =
      build_volume_model(read_volume("/usr/share/doc/invesalius-examples/examples/Cranium.inv3"));
  return m;
}

void BM_EdtWithFeatures(benchmark::State& state) {
  const Mask& bone = cranium().segmentation.bone;
  std::vector<std::int64_t> nearest;
  for (auto _ : state) benchmark::DoNotOptimize(squared_distance_mm2(bone, &nearest));
  state.counters["voxels"] = static_cast<double>(bone.geom.n_voxels());
}

void BM_VdbBoneSdf(benchmark::State& state) {
  const VolumeModel& m = cranium();
  const double voxel = m.segmentation.working.geom.spacing_mm.minCoeff();
  const double band = state.range(0) > 0 ? state.range(0) : 3 * voxel;
  std::size_t active = 0;
  for (auto _ : state) {
    const auto sdf = SignedDistanceField::from_mesh(m.bone, voxel, band, 3 * voxel);
    active = sdf.n_active_voxels();
  }
  state.counters["active_voxels"] = static_cast<double>(active);
  state.counters["faces"] = static_cast<double>(m.bone.n_faces());
}

}  // namespace

BENCHMARK(BM_EdtWithFeatures)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_VdbBoneSdf)->Arg(0)->Arg(40)->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();

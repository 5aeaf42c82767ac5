// The volume pipeline stage by stage: read, segment, cylindrical maps, surfaces, write; on the
// demo patient (Cranium.inv3) and on a 512 x 512 x 300 phantom CT. Reports voxels, cells and
// peak memory as counters.
//   build/bench/bench_volume_model --benchmark_counters_tabular=true
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <filesystem>
#include <map>

#include "caps/volume/model.hpp"
#include "caps/volume/phantom.hpp"
#include "caps/volume/read_volume.hpp"

namespace fs = std::filesystem;
using namespace caps;

namespace {

double peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

const fs::path kCranium = "/usr/share/doc/invesalius-examples/examples/Cranium.inv3";

// Inputs, made once: the phantom is written as uncompressed NIfTI so "read" measures reading.
const fs::path& input(const std::string& name) {
  static std::map<std::string, fs::path> paths;
  auto it = paths.find(name);
  if (it != paths.end()) return it->second;
  fs::path p = kCranium;
  if (name == "phantom512") {
    p = fs::temp_directory_path() / "caps_bench_phantom512.nii";
    if (!fs::exists(p)) {
      PhantomOptions o;
      o.dims = {512, 512, 300};
      o.spacing_mm = {0.5, 0.5, 0.8};
      write_nifti(make_phantom(o), p);
    }
  }
  return paths[name] = p;
}

void counters(benchmark::State& state, const Volume& v) {
  state.counters["voxels"] = static_cast<double>(v.geom.n_voxels());
  state.counters["peak_MB"] = peak_rss_mb();
}

void BM_Read(benchmark::State& state, const std::string& name) {
  Volume v;
  for (auto _ : state) v = read_volume(input(name));
  counters(state, v);
}

void BM_Segment(benchmark::State& state, const std::string& name) {
  const Volume v = read_volume(input(name));
  for (auto _ : state) benchmark::DoNotOptimize(segment_head(v));
  counters(state, v);
}

void BM_Maps(benchmark::State& state, const std::string& name) {
  const Volume v = read_volume(input(name));
  const Segmentation seg = segment_head(v);
  const CylinderAxis axis = fit_axis(seg);
  for (auto _ : state) benchmark::DoNotOptimize(cylindrical_maps(v, seg, axis));
  counters(state, v);
  state.counters["cells"] = 512 * 256;
}

// The same without the tissue layers: their cost, measured under the same machine load.
void BM_MapsWithoutLayers(benchmark::State& state, const std::string& name) {
  const Volume v = read_volume(input(name));
  const Segmentation seg = segment_head(v);
  const CylinderAxis axis = fit_axis(seg);
  MapOptions o;
  o.layers.measure = false;
  for (auto _ : state) benchmark::DoNotOptimize(cylindrical_maps(v, seg, axis, o));
  counters(state, v);
  state.counters["cells"] = 512 * 256;
}

void BM_WholeModel(benchmark::State& state, const std::string& name) {
  const Volume v = read_volume(input(name));
  for (auto _ : state) benchmark::DoNotOptimize(build_volume_model(v));
  counters(state, v);
}

void BM_ReadBuildWrite(benchmark::State& state, const std::string& name) {
  const fs::path out = fs::temp_directory_path() / "caps_bench_model";
  Volume v;
  for (auto _ : state) {
    v = read_volume(input(name));
    write_model(build_volume_model(v), out, true);
  }
  counters(state, v);
  fs::remove_all(out);
}

}  // namespace

BENCHMARK_CAPTURE(BM_Read, cranium, std::string("cranium"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Segment, cranium, std::string("cranium"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Maps, cranium, std::string("cranium"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_MapsWithoutLayers, cranium, std::string("cranium"))
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_WholeModel, cranium, std::string("cranium"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ReadBuildWrite, cranium, std::string("cranium"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Read, phantom512, std::string("phantom512"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Segment, phantom512, std::string("phantom512"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Maps, phantom512, std::string("phantom512"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_MapsWithoutLayers, phantom512, std::string("phantom512"))
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_WholeModel, phantom512, std::string("phantom512"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ReadBuildWrite, phantom512, std::string("phantom512"))->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();

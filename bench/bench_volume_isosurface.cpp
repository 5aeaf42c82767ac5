// Isosurface, Taubin smoothing and decimation on a synthetic 512x512x300 CT-like head.
//
//   cmake -S . -B build-iso -DCMAKE_BUILD_TYPE=Release -DCAPS_BUILD_BENCHMARKS=ON
//   cmake --build build-iso --target bench_volume_isosurface -j2
//   build-iso/bench/bench_volume_isosurface --benchmark_repetitions=5 \
//       --benchmark_report_aggregates_only=true
//   build-iso/bench/bench_volume_isosurface --caps_write_raw=/tmp/head.raw   # for the VTK run
#include "caps/volume/isosurface.hpp"

#include <benchmark/benchmark.h>
#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>

namespace {

constexpr float kSkinHu = -400.0f;

// An ellipsoidal head: air -1000 HU outside, soft tissue 40 HU inside, a 6 mm bone shell of
// 1000 HU under 8 mm of tissue; a 1 mm partial-volume ramp at each interface, low-frequency
// bumps on the outline (so that the surface is not a quadric), and +-15 HU deterministic noise.
caps::Volume make_head() {
  caps::Volume v;
  v.geom.dims = {512, 512, 300};
  v.geom.spacing_mm = {0.5, 0.5, 1.0};
  v.geom.origin_lps = {-127.75, -127.75, -149.5};
  v.source = "synthetic head";
  v.format = "phantom";
  v.modality = caps::Modality::CT;
  v.data.resize(v.geom.n_voxels());
  const Eigen::Vector3d semi(78.0, 98.0, 115.0);
  tbb::parallel_for(tbb::blocked_range<int>(0, v.geom.dims[2]), [&](const auto& r) {
    for (int k = r.begin(); k < r.end(); ++k)
      for (int j = 0; j < v.geom.dims[1]; ++j)
        for (int i = 0; i < v.geom.dims[0]; ++i) {
          const Eigen::Vector3d p = v.index_to_lps(Eigen::Vector3d(i, j, k));
          const double rho = p.cwiseQuotient(semi).norm();
          const double theta = std::atan2(p.y(), p.x()),
                       phi = std::acos(std::clamp(p.z() / (rho * semi.z() + 1e-9), -1.0, 1.0));
          const double bump = 1.0 + 0.04 * std::sin(3 * theta) * std::sin(2 * phi) +
                              0.02 * std::cos(5 * theta + 1.0) * std::sin(4 * phi);
          // Approximate signed depth below the skin, mm (positive inside).
          const double depth = (bump - rho) * 100.0;
          auto ramp = [](double d) { return std::clamp(0.5 + d, 0.0, 1.0); };  // 1 mm wide
          double hu = -1000.0 + 1040.0 * ramp(depth);
          hu += 960.0 * ramp(depth - 8.0) * ramp(14.0 - depth);
          const std::uint32_t h = (std::uint32_t(i) * 73856093u) ^ (std::uint32_t(j) * 19349663u) ^
                                  (std::uint32_t(k) * 83492791u);
          hu += double(h % 31u) - 15.0;
          v.at(i, j, k) = float(hu);
        }
  });
  return v;
}

const caps::Volume& head() {
  static const caps::Volume v = make_head();
  return v;
}

void BM_Isosurface(benchmark::State& state) {
  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, state.range(0));
  const caps::Volume& v = head();
  caps::TriMesh m;
  for (auto _ : state) {
    m = caps::extract_isosurface(v, kSkinHu);
    benchmark::DoNotOptimize(m.F.data());
  }
  state.counters["voxels"] = double(v.data.size());
  state.counters["triangles"] = double(m.n_faces());
  state.counters["vertices"] = double(m.n_vertices());
  state.counters["voxels_per_s"] =
      benchmark::Counter(double(v.data.size()), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_Isosurface)
    ->Arg(1)
    ->Arg(2)
    ->ArgName("threads")
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_Taubin10(benchmark::State& state) {
  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, state.range(0));
  caps::TriMesh m = caps::extract_isosurface(head(), kSkinHu);
  for (auto _ : state) {
    caps::smooth_taubin(m, 10);  // in place: the cost does not depend on the positions
    benchmark::DoNotOptimize(m.V.data());
  }
  state.counters["triangles"] = double(m.n_faces());
}
BENCHMARK(BM_Taubin10)
    ->Arg(1)
    ->Arg(2)
    ->ArgName("threads")
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_Decimate20(benchmark::State& state) {
  const caps::TriMesh m = caps::extract_isosurface(head(), kSkinHu);
  caps::TriMesh d;
  for (auto _ : state) {
    d = caps::decimate(m, 0.2);
    benchmark::DoNotOptimize(d.F.data());
  }
  state.counters["triangles_in"] = double(m.n_faces());
  state.counters["triangles_out"] = double(d.n_faces());
}
BENCHMARK(BM_Decimate20)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);

}  // namespace

int main(int argc, char** argv) {
  const std::string flag = "--caps_write_raw=";
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    if (arg.rfind(flag, 0) != 0) continue;
    // Raw float32, native (little) endian, i fastest: the exact volume the benchmark uses.
    const caps::Volume& v = head();
    std::ofstream out(arg.substr(flag.size()), std::ios::binary);
    out.write(reinterpret_cast<const char*>(v.data.data()),
              std::streamsize(v.data.size() * sizeof(float)));
    std::printf("wrote %dx%dx%d float32, spacing 0.5 0.5 1.0 mm, iso %g\n", v.geom.dims[0],
                v.geom.dims[1], v.geom.dims[2], double(kSkinHu));
    return out ? 0 : 1;
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}

// Picking on the skin: building the AABB tree of a 512 x 256 model's range mesh, and picks per
// second on one core (rays from cameras around the head through random pixels; hit_fraction says how many hit).
//   build/bench/bench_surface --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <cmath>
#include <random>

#include "caps/core/units.hpp"
#include "caps/surface/picking.hpp"

using namespace caps;

namespace {

// A head-like range image: an ellipsoid with bumps, 512 x 256 like a Cyberware scan.
PatientModel head_model() {
  CylindricalMaps m;
  m.grid.n_theta = 512;
  m.grid.n_z = 256;
  m.grid.z0_mm = -110;
  m.grid.dz_mm = 220.0 / 255;
  const auto n = m.grid.size();
  m.r_skin.resize(n);
  m.r_bone.resize(n);
  m.thickness.assign(n, 6.0f);
  m.thickness_normal.assign(n, 6.0f);
  m.flags.assign(n, 0);
  m.measured_skin.assign(n, 1);
  m.measured_bone.assign(n, 1);
  for (int k = 0; k < m.grid.n_z; ++k)
    for (int j = 0; j < m.grid.n_theta; ++j) {
      const double th = deg_to_rad(m.grid.theta_deg(j)), z = m.grid.z_mm(k);
      const double e = std::sqrt(std::max(0.0, 1 - std::pow(z / 115.0, 2)));
      const double r = e * 95.0 / std::sqrt(std::pow(std::cos(th) / 1.0, 2) +
                                            std::pow(std::sin(th) / 0.8, 2)) +
                       3 * std::sin(5 * th) * std::cos(z / 17);
      m.r_skin[m.grid.index(j, k)] = static_cast<float>(std::max(1.0, r));
      m.r_bone[m.grid.index(j, k)] = static_cast<float>(std::max(0.0, r - 6));
    }
  return PatientModel(m);
}

std::vector<Ray> camera_rays(std::size_t count) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> angle(-kPi, kPi), px(0, 640), py(0, 480), h(-60, 60);
  std::vector<Ray> rays;
  rays.reserve(count);
  while (rays.size() < count) {
    const double a = angle(rng);
    const Camera cam = Camera::look_at({500 * std::sin(a), -500 * std::cos(a), h(rng)}, {0, 0, 0},
                                       {0, 0, 1}, 20, 640, 480);
    for (int i = 0; i < 64; ++i) rays.push_back(cam.ray(px(rng), py(rng)));
  }
  return rays;
}

void BM_BuildSkinPicker(benchmark::State& state) {
  const PatientModel model = head_model();
  for (auto _ : state) {
    SkinPicker picker(model);
    benchmark::DoNotOptimize(picker.mesh().n_faces());
  }
  state.counters["triangles"] = 2.0 * 512 * 256;
}
BENCHMARK(BM_BuildSkinPicker)->Unit(benchmark::kMillisecond);

void BM_Pick(benchmark::State& state) {
  const PatientModel model = head_model();
  const SkinPicker picker(model);
  const auto rays = camera_rays(1 << 14);
  std::size_t i = 0, hits = 0, picks = 0;
  for (auto _ : state) {
    const SkinHit h = picker.pick(rays[i++ & (rays.size() - 1)]);
    hits += h.hit;
    ++picks;
    benchmark::DoNotOptimize(h);
  }
  state.counters["picks_per_s"] = benchmark::Counter(double(picks), benchmark::Counter::kIsRate);
  state.counters["hit_fraction"] = double(hits) / double(std::max<std::size_t>(1, picks));
}
BENCHMARK(BM_Pick);

void BM_PickBruteForce(benchmark::State& state) {
  const PatientModel model = head_model();
  const SkinPicker picker(model);
  const auto rays = camera_rays(256);
  std::size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(first_hit_brute_force(picker.mesh(), rays[i++ & 255]));
  state.counters["picks_per_s"] = benchmark::Counter(double(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_PickBruteForce)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();

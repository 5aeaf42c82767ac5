// The displacement-mapped skin of a real simulation: making the drawn skin (the range image
// resampled from the smoothed isosurface, slice terraces filtered), building the skin, and one
// 800 x 800 image (2 x 2 samples) of the plan and front views; CPU is the whole process's (both
// cores), Time the wall clock. Needs a model directory and a
// `caps simulate` output on it (docs/benchmarks.md, "Rendering"):
//   build/bench/bench_render --caps_model=out/cranium --caps_result=out/ellipse
// --caps_report also prints the pictures' measures: the terrace RMS of the forehead (range image
// as measured, resampled, filtered) and the pixels of the plan and oblique views where pre and
// post differ by more than 1 and 6 grey levels although the skin moved less than 0.01 mm there;
// --caps_z=Z0,Z1 sets the forehead's z range (mm, default 70,110: Cranium above the brows).
#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstdlib>
#include <string>

#include "caps/fem/mesh_io.hpp"
#include "caps/fem/result_io.hpp"
#include "caps/render/drawn_skin.hpp"
#include "caps/render/render.hpp"
#include "caps/render/skin_surface.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/volume/mesh_io.hpp"

using namespace caps;
using namespace caps::render;

namespace {

std::string g_model, g_result;
double g_forehead[2] = {70.0, 110.0};  // Cranium: the forehead above the brows

struct Case {
  PatientModel model;
  fem::Mesh mesh;
  Eigen::MatrixX3d u;
};

const Case& the_case() {
  static const Case c = [] {
    fem::Mesh mesh = fem::read_mesh_dir(g_result);
    Eigen::MatrixX3d u = fem::read_result_displacement(g_result, mesh.n_nodes());
    return Case{PatientModel::load(g_model), std::move(mesh), std::move(u)};
  }();
  return c;
}

const DrawnSkin& drawn() {
  static const DrawnSkin d = load_drawn_skin(the_case().model, g_model);
  return d;
}

const SkinSurfaces& skin() {
  static const SkinSurfaces s = [] {
    const Case& c = the_case();
    return displaced_skin(c.model, c.mesh, &c.u, full_resolution_subdivisions(c.model, c.mesh),
                          &drawn());
  }();
  return s;
}

bool have_inputs(benchmark::State& state) {
  if (!g_model.empty() && !g_result.empty()) return true;
  state.SkipWithError("give --caps_model=MODEL_DIR --caps_result=SIMULATION_DIR");
  return false;
}

void BM_LoadDrawnSkin(benchmark::State& state) {
  if (!have_inputs(state)) return;
  for (auto _ : state) benchmark::DoNotOptimize(load_drawn_skin(the_case().model, g_model));
}
BENCHMARK(BM_LoadDrawnSkin)->MeasureProcessCPUTime()->UseRealTime()->Unit(benchmark::kMillisecond);

void BM_DisplacedSkin(benchmark::State& state) {
  if (!have_inputs(state)) return;
  const Case& c = the_case();
  const int n = full_resolution_subdivisions(c.model, c.mesh);
  for (auto _ : state) benchmark::DoNotOptimize(displaced_skin(c.model, c.mesh, &c.u, n, &drawn()));
  state.counters["triangles"] = static_cast<double>(skin().pre.F.rows());
}
BENCHMARK(BM_DisplacedSkin)->MeasureProcessCPUTime()->UseRealTime()->Unit(benchmark::kMillisecond);

void BM_RenderView800(benchmark::State& state) {
  if (!have_inputs(state)) return;
  const View view = static_cast<View>(state.range(0));
  const Camera cam = standard_camera(view, the_case().model, skin(), 800, 800);
  for (auto _ : state) benchmark::DoNotOptimize(render_skin(skin(), 1.0, skin().color, cam));
  state.SetLabel(view_name(view));
}
BENCHMARK(BM_RenderView800)
    ->Arg(static_cast<int>(View::Plan))
    ->Arg(static_cast<int>(View::Front))
    ->MeasureProcessCPUTime()
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

// Pixels of `view` where pre and post differ by more than `levels` grey levels (any channel)
// although every vertex of the triangles hit there and in the 8 neighbouring pixels (pre and post)
// moved less than 0.01 mm.
int unmoved_differences(View view, int levels) {
  const SkinSurfaces& s = skin();
  const Camera cam = standard_camera(view, the_case().model, s, 800, 800);
  const RgbImage pre = render_skin(s, 0.0, s.color, cam), post = render_skin(s, 1.0, s.color, cam);
  const PixelHits hp = pixel_hits(s.pre, cam), hq = pixel_hits(s.post, cam);
  const Eigen::VectorXd moved = (s.post.V - s.pre.V).rowwise().norm();
  auto still = [&](const PixelHits& h, int x, int y) {
    const int f = h.face[static_cast<std::size_t>(y) * h.width + x];
    if (f < 0) return false;
    for (int k = 0; k < 3; ++k)
      if (moved[s.pre.F(f, k)] >= 0.01) return false;
    return true;
  };
  int count = 0;
  for (int y = 1; y + 1 < 800; ++y)
    for (int x = 1; x + 1 < 800; ++x) {
      bool ok = true;
      for (int dy = -1; dy <= 1 && ok; ++dy)
        for (int dx = -1; dx <= 1 && ok; ++dx)
          ok = still(hp, x + dx, y + dy) && still(hq, x + dx, y + dy);
      if (!ok) continue;
      const std::size_t i = (static_cast<std::size_t>(y) * 800 + x) * 3;
      for (int c = 0; c < 3; ++c)
        if (std::abs(int(pre.rgb[i + c]) - int(post.rgb[i + c])) > levels) {
          ++count;
          break;
        }
    }
  return count;
}

void report() {
  const PatientModel& m = the_case().model;
  const PatientModel resampled = [] {
    const auto iso = read_ply(std::filesystem::path(g_model) / "skin.ply");
    return drawn_skin(the_case().model, &iso).range;
  }();
  // the forehead: 30 degrees either side of the front, z in g_forehead (mm, the model's frame)
  const double th = 0.0, z0 = g_forehead[0], z1 = g_forehead[1], face_z = 0.0;
  const std::string where = "theta -30..30 deg, z " + std::to_string(int(z0)) + ".." +
                            std::to_string(int(z1)) + " mm";
  std::printf("terrace RMS (%s):\n", where.c_str());
  std::printf("  r_skin as measured      %.3f deg\n", terrace_rms_deg(m, th - 30, th + 30, face_z + z0, face_z + z1));
  std::printf("  resampled (isosurface)  %.3f deg\n", terrace_rms_deg(resampled, th - 30, th + 30, face_z + z0, face_z + z1));
  std::printf("  drawn (box filter)      %.3f deg\n", terrace_rms_deg(drawn().range, th - 30, th + 30, face_z + z0, face_z + z1));
  for (View v : {View::Plan, View::Oblique})
    std::printf("%s: %d pixels > 1 level, %d > 6 levels where the skin moved < 0.01 mm\n",
                view_name(v), unmoved_differences(v, 1), unmoved_differences(v, 6));
}

}  // namespace

int main(int argc, char** argv) {
  bool do_report = false;
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a.rfind("--caps_model=", 0) == 0) g_model = a.substr(13);
    else if (a.rfind("--caps_result=", 0) == 0) g_result = a.substr(14);
    else if (a == "--caps_report") do_report = true;
    else if (a.rfind("--caps_z=", 0) == 0)
      std::sscanf(a.c_str() + 9, "%lf,%lf", &g_forehead[0], &g_forehead[1]);
    else argv[kept++] = argv[i];
  }
  argc = kept;
  if (do_report && !g_model.empty() && !g_result.empty()) report();
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}

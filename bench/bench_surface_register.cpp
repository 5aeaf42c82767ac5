// Registering a 20k-vertex face scan onto the demo patient's skin (Cranium): the face of the
// model's skin.ply, decimated to about 20,000 vertices, moved by 12 degrees and (25, -40, 15) mm,
// with 0.2 mm of noise, registered back by register_scan() (FPFH + RANSAC, then ICP). Counters:
// the scan's and the skin's vertices, the RMS and the pose error (mm).
//   scripts/demo.sh   (or build/tools/caps model from-volume .../Cranium.inv3 -o out/cranium)
//   CAPS_BENCH_MODEL=out/cranium build/bench/bench_surface_register
#include <benchmark/benchmark.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <random>

#include "caps/core/units.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/surface/register.hpp"
#include "caps/volume/isosurface.hpp"
#include "caps/volume/mesh_io.hpp"

using namespace caps;
namespace fs = std::filesystem;

namespace {

std::string model_dir() {
  const char* m = std::getenv("CAPS_BENCH_MODEL");
  return m ? m : "out/cranium";
}

struct Case {
  TriMesh skin, face, scan;
  Eigen::Matrix4d model_to_scan = Eigen::Matrix4d::Identity();
};

const Case& the_case() {
  static const Case c = [] {
    Case c;
    const PatientModel model = PatientModel::load(model_dir());
    c.skin = read_ply(fs::path(model_dir()) / "skin.ply");
    // The face: vertices within 70 degrees of the front.
    std::vector<char> keep(c.skin.n_vertices());
    for (Eigen::Index v = 0; v < c.skin.n_vertices(); ++v)
      keep[v] = std::abs(model.to_cylindrical(c.skin.V.row(v).transpose()).theta_deg) <= 70;
    const TriMesh face = crop_mesh(c.skin, keep);
    c.face = decimate(face, std::min(1.0, 40000.0 / static_cast<double>(face.n_faces())));
    c.model_to_scan.topLeftCorner<3, 3>() =
        Eigen::AngleAxisd(deg_to_rad(12.0), Eigen::Vector3d(1, 2, 0.5).normalized()).toRotationMatrix();
    c.model_to_scan.topRightCorner<3, 1>() = Eigen::Vector3d(25, -40, 15);
    c.scan = c.face;
    std::mt19937 rng(5);
    std::normal_distribution<double> noise(0.0, 0.2);
    for (Eigen::Index v = 0; v < c.scan.n_vertices(); ++v)
      for (int d = 0; d < 3; ++d) c.scan.V(v, d) += noise(rng);
    c.scan.V = transform_points(c.model_to_scan, c.scan.V);
    return c;
  }();
  return c;
}

void BM_RegisterFaceScanToCranium(benchmark::State& state) {
  const Case& c = the_case();
  RegistrationOptions o;
  o.mm_per_unit = 1.0;
  ScanRegistration r;
  for (auto _ : state) r = register_scan(c.scan, c.skin, o);
  const Eigen::MatrixX3d back = transform_points(r.scan_to_model, transform_points(c.model_to_scan, c.face.V));
  state.counters["scan_vertices"] = static_cast<double>(c.scan.n_vertices());
  state.counters["skin_vertices"] = static_cast<double>(c.skin.n_vertices());
  state.counters["rms_mm"] = r.residual.rms_mm;
  state.counters["pose_error_mm"] = (back - c.face.V).rowwise().norm().maxCoeff();
  if (!r.same_head) state.SkipWithError(r.verdict.c_str());
}
BENCHMARK(BM_RegisterFaceScanToCranium)->Unit(benchmark::kMillisecond)->UseRealTime()->MeasureProcessCPUTime()->Iterations(3);

}  // namespace

BENCHMARK_MAIN();

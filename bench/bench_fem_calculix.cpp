// caps against CalculiX on the same finite-strain problem, side by side in one run: the mesh is
// solved by caps (neo-Hookean, sutures closed in load steps) and its .inp deck (the export caps
// writes: *HYPERELASTIC, NEO HOOKE, NLGEOM, the same initial increment, free to grow to the
// whole step as caps's steps grow) by CalculiX's ccx; both wall
// times, the CPU time of each, and how far the two displacement fields differ. Results in
// docs/benchmarks.md, "Finite strain against CalculiX".
//   build/bench/bench_fem_calculix                       (the 50.6k-DOF slab)
//   CAPS_BENCH_MESH=DIR build/bench/bench_fem_calculix   (a mesh directory: caps mesh/simulate -o DIR)
// ccx runs with OMP_NUM_THREADS=2 (the machine's cores); it must be on the PATH.
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "caps/fem/box.hpp"
#include "caps/fem/inp_io.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/fem/solve.hpp"
#include "blas_context.hpp"

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double cpu_seconds(int who) {
  rusage u{};
  getrusage(who, &u);
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

// The nodal displacements of the last block ccx printed to job.dat (#N×3, NaN if missing).
Eigen::MatrixX3d read_dat(const fs::path& dat, Eigen::Index n_nodes) {
  std::ifstream in(dat);
  std::string line;
  Eigen::MatrixX3d u = Eigen::MatrixX3d::Constant(n_nodes, 3, NAN);
  bool in_block = false;
  while (std::getline(in, line)) {
    if (line.find("displacements") != std::string::npos) {
      in_block = true;
      continue;
    }
    std::istringstream is(line);
    Eigen::Index id;
    double x, y, z;
    if (in_block && (is >> id >> x >> y >> z) && id >= 1 && id <= n_nodes) u.row(id - 1) << x, y, z;
  }
  return u;
}

caps::fem::Mesh bench_mesh() {
  if (const char* dir = std::getenv("CAPS_BENCH_MESH")) return caps::fem::read_mesh_dir(dir);
  caps::fem::BoxOptions o;  // bench_fem's slab(38): 50.6k DOF, a 4 mm slot sutured shut
  o.size_mm = {4.0 * 38, 4.0 * 38, 6.0};
  o.cells = {39, 38, 2};
  o.slot = true;
  return caps::fem::make_box_mesh(o);
}

void FiniteAgainstCalculix(benchmark::State& state) {
  const caps::fem::Mesh mesh = bench_mesh();
  const int steps = static_cast<int>(state.range(0));
  caps::fem::SolveOptions so;
  so.kinematics = caps::fem::Kinematics::Finite;
  so.newton.n_steps = steps;
  const fs::path dir = fs::temp_directory_path() / "caps_bench_fem_calculix";
  fs::remove_all(dir);
  fs::create_directories(dir);
  caps::fem::InpOptions io;
  io.finite_strain = true;
  io.increments = steps;
  caps::fem::write_inp(mesh, dir / "job.inp", io);
  setenv("OMP_NUM_THREADS", "2", 1);
  caps::fem::SolveResult r;
  double caps_wall = 0, caps_cpu = 0, ccx_wall = 0, ccx_cpu = 0;
  int ccx_status = 0;
  for (auto _ : state) {
    double c0 = cpu_seconds(RUSAGE_SELF);
    auto t0 = Clock::now();
    r = caps::fem::solve(mesh, so);
    caps_wall = std::chrono::duration<double>(Clock::now() - t0).count();
    caps_cpu = cpu_seconds(RUSAGE_SELF) - c0;
    c0 = cpu_seconds(RUSAGE_CHILDREN);
    t0 = Clock::now();
    const std::string cmd = "cd '" + dir.string() + "' && ccx -i job > ccx.log 2>&1";
    ccx_status = std::system(cmd.c_str());
    ccx_wall = std::chrono::duration<double>(Clock::now() - t0).count();
    ccx_cpu = cpu_seconds(RUSAGE_CHILDREN) - c0;
  }
  const Eigen::MatrixX3d u = read_dat(dir / "job.dat", mesh.n_nodes());
  const double scale = r.displacement_mm.rowwise().norm().maxCoeff();
  const bool ccx_done = ccx_status == 0 && u.allFinite();
  state.counters["dofs"] = static_cast<double>(r.n_dofs);
  state.counters["load_steps"] = static_cast<double>(r.newton_steps.size());
  state.counters["newton_iterations"] = r.newton_iterations;
  state.counters["factorizations"] = r.factorizations;
  state.counters["caps_s"] = caps_wall;
  state.counters["caps_cpu_s"] = caps_cpu;
  // where caps's time goes (s): assembly (structure, tangents, residuals), analysis,
  // factorizations, solves (with the reused factor: refinement or CG), recovery
  state.counters["t_assembly"] = r.timings.assembly_s;
  state.counters["t_analysis"] = r.timings.analysis_s;
  state.counters["t_factor"] = r.timings.factorization_s;
  state.counters["t_solve"] = r.timings.solve_s;
  state.counters["t_recovery"] = r.timings.recovery_s + r.timings.constraints_s;
  state.counters["ccx_s"] = ccx_wall;
  state.counters["ccx_cpu_s"] = ccx_cpu;
  state.counters["speedup"] = ccx_wall / caps_wall;
  // max |u_caps - u_ccx| over the largest displacement (NaN when ccx did not finish)
  state.counters["difference"] =
      ccx_done ? (r.displacement_mm - u).cwiseAbs().maxCoeff() / scale : NAN;
  state.SetLabel(ccx_done ? "ccx finished" : "ccx failed: see " + (dir / "ccx.log").string());
}

}  // namespace

// range(0) = initial load steps (caps) = initial increments (ccx); both grow after easy steps.
BENCHMARK(FiniteAgainstCalculix)->Arg(10)->Unit(benchmark::kSecond)->Iterations(1);

BENCHMARK_MAIN();

// Solver (fem) benchmark: assembly, analysis, factorization, solve and peak memory against
// problem size, MUMPS against CHOLMOD. Results in docs/benchmarks.md, section "Solver (fem)".
//   build-fem/bench/bench_fem --benchmark_filter='Slab/.*' --benchmark_min_time=1x
// Meshes: "slab" = a skin-like 2-layer plate of Hex20 (the shape caps solves: wide and thin,
// bottom fixed, a sutured slot); "cube" = a cube of Hex20 (the CalculiX comparison case).
#include <benchmark/benchmark.h>

#include <cmath>

#include "caps/fem/box.hpp"
#include "caps/fem/elements.hpp"
#include "caps/fem/material.hpp"
#include "caps/fem/solve.hpp"
#include "blas_context.hpp"

namespace {

using caps::fem::BoxOptions;
using caps::fem::SolverKind;

void run(benchmark::State& state, const BoxOptions& o,
         caps::fem::Kinematics kinematics = caps::fem::Kinematics::Linear) {
  const caps::fem::Mesh mesh = caps::fem::make_box_mesh(o);
  caps::fem::SolveOptions so;
  so.kinematics = kinematics;
  so.solver = state.range(1) == 1 ? SolverKind::Cholmod : SolverKind::Mumps;
  so.mixed_precision = state.range(1) == 0;
  so.mumps_ordering = static_cast<int>(state.range(2));
  caps::fem::SolveResult r;
  for (auto _ : state) {
    r = caps::fem::solve(mesh, so);
    benchmark::DoNotOptimize(r.displacement_mm.data());
  }
  state.counters["dofs"] = static_cast<double>(r.n_dofs);
  state.counters["equations"] = static_cast<double>(r.n_equations);
  state.counters["constraints_s"] = r.timings.constraints_s;
  state.counters["assembly_s"] = r.timings.assembly_s;
  state.counters["analysis_s"] = r.timings.analysis_s;
  state.counters["factor_s"] = r.timings.factorization_s;
  state.counters["solve_s"] = r.timings.solve_s;
  state.counters["recovery_s"] = r.timings.recovery_s;
  state.counters["total_s"] = r.timings.total_s;
  state.counters["factor_nnz_M"] = static_cast<double>(r.factor_nonzeros) * 1e-6;
  state.counters["peak_rss_MB"] = r.peak_memory_mb;
  state.counters["cg_iterations"] = r.refinement_iterations;
  state.counters["residual"] = r.relative_residual;
  if (kinematics == caps::fem::Kinematics::Finite) {
    state.counters["load_steps"] = static_cast<double>(r.newton_steps.size());
    state.counters["newton_iterations"] = r.newton_iterations;
    state.counters["factorizations"] = r.factorizations;
  }
  state.SetLabel(so.solver == SolverKind::Cholmod ? "cholmod"
                 : r.fell_back_to_double   ? "mumps mixed (fell back to double)"
                                           : "mumps " + r.precision);
}

// range(0) = cells per side in x-y, range(1) = 0 MUMPS mixed precision / 1 CHOLMOD / 2 MUMPS
// double, range(2) = ICNTL(7).
BoxOptions slab(int n) {
  BoxOptions o;
  o.size_mm = {4.0 * n, 4.0 * n, 6.0};
  o.cells = {n | 1, n, 2};
  o.slot = true;
  return o;
}

void Slab(benchmark::State& state) { run(state, slab(static_cast<int>(state.range(0)))); }

// The slab's slot (4 mm wide) closed at finite strain (neo-Hookean, 10 load steps).
void SlabFinite(benchmark::State& state) {
  run(state, slab(static_cast<int>(state.range(0))), caps::fem::Kinematics::Finite);
}

// One finite-strain Hex20 (27 Gauss points, neo-Hookean): internal force and consistent
// tangent (range(0) = 1) or the force alone (0), at a distorted element stretched 10-20 %: the
// kernel of every Newton assembly.
void ElementFinite(benchmark::State& state) {
  const caps::fem::Mesh cell = caps::fem::make_box_mesh([] {
    BoxOptions o;
    o.size_mm = {4, 4, 3};
    o.cells = {1, 1, 1};
    return o;
  }());
  Eigen::MatrixX3d X = caps::fem::element_coordinates(cell, 0);
  Eigen::VectorXd u(3 * X.rows());
  for (Eigen::Index a = 0; a < X.rows(); ++a) {
    X.row(a) += 0.2 * Eigen::RowVector3d(std::sin(a), std::cos(2.0 * a), std::sin(3.0 * a));
    u.segment<3>(3 * a) = Eigen::Vector3d(0.1 * X(a, 0) + 0.05 * X(a, 1), 0.2 * X(a, 1), -0.1 * X(a, 2));
  }
  const caps::fem::NeoHookean material(0.1, 0.45);
  const bool tangent = state.range(0) == 1;
  for (auto _ : state) {
    const auto r = caps::fem::element_finite_response(caps::fem::ElementType::Hex20, X, material, u, 0, tangent);
    benchmark::DoNotOptimize(r.f.data());
  }
}

void Cube(benchmark::State& state) {
  BoxOptions o;
  const int n = static_cast<int>(state.range(0));
  o.size_mm = {40, 40, 40};
  o.cells = {n, n, n};
  run(state, o);
}

}  // namespace

// Slab cells 23 -> 18.5k dofs, 38 -> 50.6k, 51 -> 88k, 73 -> 179k, 127 -> ~540k.
BENCHMARK(Slab)->ArgsProduct({{23, 51, 73, 127}, {0, 1}, {4}})->Unit(benchmark::kMillisecond)->Iterations(1);
// About 50k DOF, the target size, with each MUMPS ordering.
BENCHMARK(Slab)->ArgsProduct({{38, 95}, {0, 1, 2}, {4}})->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK(Slab)->ArgsProduct({{38}, {0}, {0, 3, 5, 7}})->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK(Slab)->ArgsProduct({{51}, {0}, {0, 2, 3, 5, 7}})->Unit(benchmark::kMillisecond)->Iterations(1);
// Cube 8 -> ~10k dofs, 13 -> ~30k, 16 -> ~56k (the CalculiX 54k-dof case).
BENCHMARK(SlabFinite)->ArgsProduct({{23, 38}, {0, 1}, {4}})->Unit(benchmark::kMillisecond)->Iterations(1);

BENCHMARK(ElementFinite)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

BENCHMARK(Cube)->ArgsProduct({{8, 13, 16}, {0, 1, 2}, {4}})->Unit(benchmark::kMillisecond)->Iterations(1);

BENCHMARK_MAIN();

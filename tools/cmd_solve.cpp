// caps solve: linear elastic solve of a caps-mesh directory with fixed nodes and sutures.
// caps fem box: write a small test mesh directory (a box, optionally with a sutured slot).
//   caps fem box -o /tmp/slot-mesh --size 30,20,6 --cells 5,6,2 --slot
//   caps solve /tmp/slot-mesh -o /tmp/slot-result
//   caps solve /tmp/slot-mesh -o /tmp/slot-result --solver cholmod --E 50 --nu 0.45 --force --json
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/fem/box.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/fem/result_io.hpp"
#include "caps/fem/solve.hpp"
#include "commands.hpp"

namespace caps::cli {
namespace {

struct SolveArgs {
  std::string mesh, output, solver = "mumps", precision = "mixed";
  double E_kpa = -1, nu = -1;
};

struct BoxArgs {
  std::string output, size = "40,10,10", cells = "8,2,2";
  bool slot = false, wedges = false;
};

void run_solve(const SolveArgs& a, const Common& common) {
  fem::SolveOptions o;
  o.solver = fem::parse_solver(a.solver);
  o.mixed_precision = fem::parse_precision(a.precision);
  OutputDirectory out(a.output, common.force);
  fem::Mesh mesh = fem::read_mesh_dir(a.mesh);
  if (a.E_kpa >= 0 || a.nu >= 0)
    for (auto& [layer, m] : mesh.materials)
      m = fem::LinearElastic(a.E_kpa >= 0 ? a.E_kpa * 1e-3 : m.E_mpa(), a.nu >= 0 ? a.nu : m.nu(),
                             "--E/--nu");
  const fem::SolveResult r = fem::solve(mesh, o);
  fem::write_result_dir(mesh, r, out.path());
  out.commit();
  nlohmann::json j{{"output", a.output},
                   {"solver", r.solver},
                   {"equations", r.n_equations},
                   {"max_displacement_mm", r.displacement_mm.rowwise().norm().maxCoeff()},
                   {"max_von_mises_mpa", r.von_mises_mpa.maxCoeff()},
                   {"total_suture_force_n", r.total_suture_force_n},
                   {"strain_energy_mj", r.strain_energy_mj},
                   {"total_s", r.timings.total_s}};
  if (common.json)
    std::cout << j.dump(2) << "\n";
  else if (!common.quiet)
    std::cerr << "caps solve: " << r.n_equations << " equations (" << r.solver << ") in "
              << r.timings.total_s << " s; max displacement " << j["max_displacement_mm"]
              << " mm, closing force " << r.total_suture_force_n << " N -> " << a.output << "\n";
}

void run_box(const BoxArgs& a, const Common& common) {
  fem::BoxOptions o;
  const auto s = parse_triple(a.size, "--size");
  const auto c = parse_triple(a.cells, "--cells");
  for (int k = 0; k < 3; ++k) {
    if (c[k] != static_cast<int>(c[k]))
      throw InvalidInput(cat("--cells ", a.cells, ": cell counts must be whole numbers"));
    o.size_mm[k] = s[k];
    o.cells[k] = static_cast<int>(c[k]);
  }
  o.slot = a.slot;
  o.wedges = a.wedges;
  OutputDirectory out(a.output, common.force);
  const fem::Mesh m = fem::make_box_mesh(o);
  fem::write_mesh_dir(m, out.path());
  out.commit();
  if (common.json)
    std::cout << nlohmann::json{{"output", a.output}, {"nodes", m.n_nodes()},
                                {"elements", m.n_elements()}, {"sutures", m.sutures.size()}}
                     .dump(2)
              << "\n";
}

}  // namespace

void add_solve(CLI::App& app, Common& common, Action& action) {
  auto* cmd = app.add_subcommand(
      "solve", "Solve a caps-mesh directory (linear elasticity, fixed nodes, sutures); writes "
               "result.vtu and result.json.\nExample: caps solve mesh -o result --solver mumps");
  auto a = std::make_shared<SolveArgs>();
  cmd->add_option("MESH_DIR", a->mesh, "mesh directory (mesh.json + mesh.vtu)")->required();
  cmd->add_option("-o,--output", a->output, "result directory to create")->required();
  cmd->add_option("--solver", a->solver, "mumps or cholmod")->capture_default_str();
  cmd->add_option("--precision", a->precision,
                  "mixed (a single-precision factorization refined to double accuracy; falls back to double by itself when that is not enough) or double; MUMPS only")
      ->capture_default_str();
  cmd->add_option("--E", a->E_kpa, "Young's modulus in kPa for every layer (overrides mesh.json)");
  cmd->add_option("--nu", a->nu, "Poisson's ratio for every layer, 0 <= nu <= 0.499");
  add_common_flags(cmd, common, true);
  cmd->callback([&common, &action, a] { action = [&common, a] { run_solve(*a, common); }; });

  auto* fem_cmd = app.add_subcommand("fem", "Finite-element utilities.");
  fem_cmd->require_subcommand(1);
  auto* box = fem_cmd->add_subcommand(
      "box", "Write a box mesh directory of Hex20 (or Wedge15) elements, bottom fixed, "
             "optionally with a sutured slot.\nExample: caps fem box -o m --cells 5,6,2 --slot");
  auto b = std::make_shared<BoxArgs>();
  box->add_option("-o,--output", b->output, "mesh directory to create")->required();
  box->add_option("--size", b->size, "box size in mm along x,y,z")->capture_default_str();
  box->add_option("--cells", b->cells, "cells along x,y,z")->capture_default_str();
  box->add_flag("--slot", b->slot, "cut a slot through the middle x column and suture it");
  box->add_flag("--wedges", b->wedges, "split every cell into two Wedge15");
  add_common_flags(box, common, true);
  box->callback([&common, &action, b] { action = [&common, b] { run_box(*b, common); }; });
}

}  // namespace caps::cli

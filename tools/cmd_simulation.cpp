// caps mesh, simulate, solve, compare and fem box: bound to app/ (caps/app/simulation.hpp).
//   caps plan new z-plasty --model /tmp/cranium --at 0,90 -o /tmp/z.json
//   caps mesh --model /tmp/cranium --plan /tmp/z.json -o /tmp/zplasty-mesh
//   caps mesh --model /tmp/cranium --border border.json -o /tmp/m --layers 3 --mesh-size 1.5 --extent 60 --rim free --force --json
//   caps solve /tmp/zplasty-mesh -o /tmp/zplasty-result --solver cholmod --E 50 --nu 0.45
//   caps simulate --model /tmp/cranium --plan /tmp/z.json -o /tmp/zplasty-result --render
//   caps compare --model /tmp/cranium --plan /tmp/e.json -o /tmp/e-compare --thickness 6
//   caps fem box -o /tmp/slot-mesh --box-size 30,20,6 --cells 5,6,2 --slot
#include "caps/app/simulation.hpp"
#include "commands.hpp"

namespace caps::cli {

void add_mesh(CLI::App& app, Common& common, Action& action) {
  add_verb(&app, "mesh",
           "Mesh a wound border on a patient model (paper section 6): mesh.vtu + mesh.json (for "
           "caps solve), mesh.inp (CalculiX), surface.png, section.png, summary.json.\n"
           "Example: caps mesh --model cranium --plan zplasty.json -o mesh",
           &app::run_mesh, common, action);
}

void add_simulate(CLI::App& app, Common& common, Action& action) {
  add_verb(&app, "simulate",
           "Mesh a plan on a patient model and solve the wound closure in one go: the mesh and "
           "result files of caps mesh and caps solve in one folder.\n"
           "Example: caps simulate --model cranium --plan zplasty.json -o result",
           &app::run_simulate, common, action);
}

void add_solve(CLI::App& app, Common& common, Action& action) {
  add_verb(&app, "solve",
           "Solve a caps-mesh directory (fixed nodes, sutures; small-strain linear elasticity, or "
           "finite strain with --material neo-hookean); writes result.vtu and result.json.\nExample: caps solve mesh -o result --solver mumps",
           &app::run_solve, common, action);
}

void add_compare(CLI::App& app, Common& common, Action& action) {
  add_verb(&app, "compare",
           "Simulate one plan with the measured soft-tissue thickness and with a constant one\n"
           "(the 1992 assumption for surface scans), on the same skin and surface mesh, and\n"
           "write report.html with a table of the differences and both results' pictures.\n"
           "Example: caps compare --model cranium --plan ellipse.json -o compare",
           &app::run_compare, common, action);
}

void add_fem(CLI::App& app, Common& common, Action& action) {
  auto* fem = app.add_subcommand("fem", "Finite-element utilities.");
  fem->require_subcommand(1);
  add_verb(fem, "box",
           "Write a box mesh directory of Hex20 (or Wedge15) elements, bottom fixed, optionally "
           "with a sutured slot.\nExample: caps fem box -o m --cells 5,6,2 --slot",
           &app::run_box, common, action);
}

}  // namespace caps::cli

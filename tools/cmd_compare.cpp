// caps compare: one plan on the measured thickness and on a constant one (the 1992 assumption),
// with a table of differences and the two results side by side in report.html.
//   caps plan new ellipse --model /tmp/cranium --at 25,105 -o /tmp/e.json
//   caps compare --model /tmp/cranium --plan /tmp/e.json -o /tmp/e-compare
//   caps compare --model /tmp/cranium --plan /tmp/e.json -o /tmp/e-compare --thickness 6 --force --json
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/fem/compare.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/render/simulation_report.hpp"
#include "caps/surface/patient_model.hpp"
#include "commands.hpp"

namespace caps::cli {
namespace {

struct CompareArgs {
  std::string model, plan, output, solver = "mumps", precision = "mixed";
  double thickness_mm = 0, size_mm = 2, undermine_mm = 0;
  int layers = 2;
};

void run_compare(const CompareArgs& a, const Common& common) {
  fem::SimulateOptions o;
  o.surface.size_mm = a.size_mm;
  o.continuum.n_layers = a.layers;
  o.continuum.undermine_mm = a.undermine_mm;
  o.solve.solver = fem::parse_solver(a.solver);
  o.solve.mixed_precision = fem::parse_precision(a.precision);
  const plan::Plan plan = plan::read_plan(a.plan);
  OutputDirectory out(a.output, common.force);
  const PatientModel model = PatientModel::load(a.model);
  const fem::Comparison c = fem::compare_thickness(model, plan, a.thickness_mm, o);
  render::write_comparison_report(c, model, o, out.path(),
                                  std::filesystem::path(a.plan).filename().string());
  out.commit();
  if (common.json) {
    std::ifstream in(std::filesystem::path(a.output) / "comparison.json");
    std::cout << in.rdbuf();
  } else if (!common.quiet) {
    const auto& m = c.measured_summary;
    const auto& k = c.constant_summary;
    std::cerr << "caps compare: closing force " << m.closing_force_n << " N (measured) vs "
              << k.closing_force_n << " N (constant " << c.constant_thickness_mm << " mm); largest "
              << "displacement " << m.max_displacement_mm << " vs " << k.max_displacement_mm
              << " mm -> " << a.output << "/report.html\n";
  }
}

}  // namespace

void add_compare(CLI::App& app, Common& common, Action& action) {
  auto a = std::make_shared<CompareArgs>();
  auto* cmd = app.add_subcommand(
      "compare", "Simulate one plan with the measured soft-tissue thickness and with a constant one\n"
                 "(the 1992 assumption for surface scans), on the same skin and surface mesh, and\n"
                 "write report.html with a table of the differences and both results' pictures.\n"
                 "Example: caps compare --model cranium --plan ellipse.json -o compare");
  cmd->add_option("--model", a->model, "patient model directory (from a volume)")->required();
  cmd->add_option("--plan", a->plan, "the plan (caps plan new)")->required();
  cmd->add_option("-o,--output", a->output, "the folder to create")->required();
  cmd->add_option("--thickness", a->thickness_mm,
                  "the constant thickness in mm (default 0: the median measured under the wound)");
  cmd->add_option("--size", a->size_mm, "mesh size at the wound (mm)")->capture_default_str();
  cmd->add_option("--layers", a->layers, "element layers from skin to bone")->capture_default_str();
  cmd->add_option("--undermine", a->undermine_mm,
                  "free the tissue from the bone within this distance of the wound (mm), as a surgeon undermines; 0 = only the sutured columns (the paper)")
      ->capture_default_str();
  cmd->add_option("--solver", a->solver, "mumps or cholmod")->capture_default_str();
  cmd->add_option("--precision", a->precision,
                  "mixed (a single-precision factorization refined to double accuracy; falls back to double by itself when that is not enough) or double; MUMPS only")
      ->capture_default_str();
  add_common_flags(cmd, common, true);
  cmd->callback([&common, &action, a] { action = [&common, a] { run_compare(*a, common); }; });
}

}  // namespace caps::cli

// caps mesh: the wound-closure mesh of a plan (or a bare wound border) on a patient model (paper
// section 6): mesh.vtu + mesh.json (for `caps solve`), mesh.inp (CalculiX / Abaqus), surface.png
// (Figure 3), section.png (Figure 4) and a summary. caps simulate: mesh and solve in one go.
//   caps plan new z-plasty --model /tmp/cranium --at 0,90 -o /tmp/z.json
//   caps mesh --model /tmp/cranium --plan /tmp/z.json -o /tmp/zplasty-mesh
//   caps simulate --model /tmp/cranium --plan /tmp/z.json -o /tmp/zplasty-result --render
//   caps mesh --model /tmp/cranium --border border.json -o /tmp/zplasty-mesh
//   caps mesh --model /tmp/cranium --border border.json -o /tmp/m --layers 3 --size 1.5 --extent 60 --rim free --force --json
//   caps solve /tmp/zplasty-mesh -o /tmp/zplasty-result
// border.json: {"loop_theta_z": [[theta_deg, z_mm], ...], "sutures": [[a, b, c, d], ...]}
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/fem/continuum_mesher.hpp"
#include "caps/fem/inp_io.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/fem/mesh_pictures.hpp"
#include "caps/fem/simulate.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/render/simulation_report.hpp"
#include "caps/surface/patient_model.hpp"
#include "commands.hpp"

namespace caps::cli {
namespace {

struct MeshArgs {
  std::string model, border, plan, output, rim = "fixed", solver = "mumps",
              precision = "mixed";
  int layers = 2;
  double size_mm = 2, extent_mm = 0, grading = 1, t1_deg = 30, t2_deg = 90, constant_mm = 0,
         stage1_angle_deg = 20, undermine_mm = 0;
  bool no_pictures = false, tension_map = false;
  bool render = false;  // simulate: also the pre- and post-operative images
};

fem::WoundBorder read_border(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw IoError(cat(path, ": cannot open the wound border file"));
  nlohmann::json j;
  try {
    in >> j;
  } catch (const std::exception& e) {
    throw InvalidInput(cat(path, ": not valid JSON (", e.what(), ")"));
  }
  fem::WoundBorder b;
  try {
    for (const auto& p : j.at("loop_theta_z")) b.loop_theta_z.emplace_back(p.at(0), p.at(1));
    if (j.contains("sutures"))
      for (const auto& s : j.at("sutures"))
        b.sutures.push_back({s.at(0).get<int>(), s.at(1).get<int>(), s.at(2).get<int>(),
                             s.at(3).get<int>()});
  } catch (const nlohmann::json::exception& e) {
    throw InvalidInput(cat(path, ": expected {\"loop_theta_z\": [[theta_deg, z_mm], ...], "
                           "\"sutures\": [[a, b, c, d], ...]} (", e.what(), ")"));
  }
  return b;
}

fem::WoundBorder border_of(const MeshArgs& a) {
  if (a.plan.empty() == a.border.empty())
    throw InvalidInput("give the wound as --plan plan.json (from caps plan new) or as --border "
                       "border.json, one of the two");
  return a.plan.empty() ? read_border(a.border) : plan::wound_border(plan::read_plan(a.plan));
}

fem::SimulateOptions options_of(const MeshArgs& a) {
  fem::SimulateOptions o;
  o.surface.size_mm = a.size_mm;
  o.surface.extent_mm = a.extent_mm;
  o.surface.t1_deg = a.t1_deg;
  o.surface.stage1_min_angle_deg = a.stage1_angle_deg;
  o.surface.t2_deg = a.t2_deg;
  o.continuum.n_layers = a.layers;
  o.continuum.grading = a.grading;
  o.continuum.rim = fem::parse_rim_condition(a.rim);
  o.continuum.constant_thickness_mm = a.constant_mm;
  o.continuum.undermine_mm = a.undermine_mm;
  o.solve.solver = fem::parse_solver(a.solver);
  o.solve.mixed_precision = fem::parse_precision(a.precision);
  return o;
}

void run_simulate(const MeshArgs& a, const Common& common) {
  const fem::SimulateOptions o = options_of(a);
  const plan::Plan plan = plan::read_plan(a.plan);
  OutputDirectory out(a.output, common.force);
  const PatientModel model = PatientModel::load(a.model);
  fem::Simulation sim = fem::simulate(model, plan, o);
  sim.wound.continuum.mesh.model = a.model;
  sim.wound.continuum.mesh.plan = a.plan;
  fem::write_simulation(sim, model, o, out.path(), std::filesystem::path(a.plan).filename().string());
  if (a.render)
    render::render_simulation(model, sim, {render::View::Front, render::View::Oblique,
                                           render::View::Side, render::View::Plan},
                              {}, out.path(), a.tension_map);
  out.commit();
  const auto& r = sim.result;
  nlohmann::json j{{"output", a.output},
                   {"elements", sim.wound.continuum.mesh.n_elements()},
                   {"nodes", sim.wound.continuum.mesh.n_nodes()},
                   {"suture_pairs", sim.wound.continuum.mesh.sutures.size()},
                   {"max_displacement_mm", r.displacement_mm.rowwise().norm().maxCoeff()},
                   {"closing_force_n", r.total_suture_force_n},
                   {"max_suture_gap_mm", sim.max_suture_gap_mm},
                   {"strain_energy_mj", r.strain_energy_mj},
                   {"solve_s", r.timings.total_s}};
  if (common.json) std::cout << j.dump(2) << "\n";
  else if (!common.quiet)
    std::cerr << "caps simulate: " << j["elements"] << " elements, closing force "
              << r.total_suture_force_n << " N, max displacement "
              << j["max_displacement_mm"].get<double>() << " mm, suture gap after closure "
              << sim.max_suture_gap_mm << " mm -> " << a.output << "\n";
}

void run_mesh(const MeshArgs& a, const Common& common) {
  const fem::SimulateOptions o = options_of(a);  // the meshing part of it
  const fem::SurfaceMeshOptions& so = o.surface;
  const fem::ContinuumMeshOptions& co = o.continuum;
  const fem::WoundBorder border = border_of(a);
  OutputDirectory out(a.output, common.force);
  const PatientModel model = PatientModel::load(a.model);
  fem::WoundMesh w = fem::mesh_wound(border, model, so, co);
  w.continuum.mesh.model = a.model;
  const std::string wound = a.plan.empty() ? a.border : a.plan;
  w.continuum.mesh.plan = wound;
  fem::write_mesh_dir(w.continuum.mesh, out.path());
  fem::write_inp(w.continuum.mesh, out.path() / "mesh.inp");
  if (!a.no_pictures) {
    fem::write_surface_mesh_png(out.path() / "surface.png", w.surface,
                                cat("caps mesh: surface mesh of ", wound));
    fem::write_cross_section_png(out.path() / "section.png", w.surface, model, co,
                                 cat("caps mesh: cross-section of ", wound));
  }
  const auto& s = w.surface;
  const auto& c = w.continuum;
  int hex = 0;
  for (const auto& e : c.mesh.elements) hex += e.type == fem::ElementType::Hex20;
  nlohmann::json j{
      {"output", a.output},
      {"surface", {{"vertices", s.n_vertices()}, {"quads", s.quality.n_quads},
                   {"triangles", s.quality.n_triangles}, {"layers", s.n_layers},
                   {"extent_mm", s.extent_mm}, {"wound_size_mm", s.wound_size_mm},
                   {"min_angle_deg", s.quality.min_angle_deg},
                   {"max_angle_deg", s.quality.max_angle_deg},
                   {"max_aspect_ratio", s.quality.max_aspect_ratio},
                   {"mean_aspect_ratio", s.quality.mean_aspect_ratio}}},
      {"continuum", {{"nodes", c.mesh.n_nodes()}, {"elements", c.mesh.n_elements()},
                     {"hex20", hex}, {"wedge15", static_cast<int>(c.mesh.n_elements()) - hex},
                     {"layers", c.n_layers}, {"fixed_nodes", c.mesh.fixed_nodes.size()},
                     {"suture_pairs", c.mesh.sutures.size()}, {"rim", a.rim},
                     {"thickness_mm", {c.min_thickness_mm, c.max_thickness_mm}},
                     {"min_jacobian", c.min_jacobian}}}};
  write_text_atomic(out.path() / "summary.json", j.dump(1) + "\n");
  out.commit();
  if (common.json)
    std::cout << j.dump(2) << "\n";
  else if (!common.quiet)
    std::cerr << "caps mesh: " << c.mesh.n_elements() << " elements (" << hex << " Hex20), "
              << c.mesh.n_nodes() << " nodes, " << c.mesh.sutures.size() << " suture pairs; "
              << "corner angles " << s.quality.min_angle_deg << "-" << s.quality.max_angle_deg
              << " deg -> " << a.output << "\n";
}

}  // namespace

void add_mesh(CLI::App& app, Common& common, Action& action) {
  auto* cmd = app.add_subcommand(
      "mesh", "Mesh a wound border on a patient model (paper section 6): mesh.vtu + mesh.json "
              "(for caps solve), mesh.inp (CalculiX), surface.png, section.png, summary.json.\n"
              "Example: caps mesh --model cranium --plan zplasty.json -o mesh");
  auto a = std::make_shared<MeshArgs>();
  cmd->add_option("--model", a->model, "patient model directory")->required();
  cmd->add_option("--plan", a->plan, "the plan (caps plan new)");
  cmd->add_option("--border", a->border,
                  "or a bare wound border JSON: {\"loop_theta_z\": [[deg, mm], ...], \"sutures\": "
                  "[[a, b, c, d], ...]}");
  cmd->add_option("-o,--output", a->output, "mesh directory to create")->required();
  cmd->add_option("--layers", a->layers, "element layers from skin to bone")->capture_default_str();
  cmd->add_option("--size", a->size_mm, "mesh size at the wound and first layer thickness (mm)")
      ->capture_default_str();
  cmd->add_option("--extent", a->extent_mm,
                  "distance from the wound to the outer rim (mm); 0 = 3 x the wound's size");
  cmd->add_option("--undermine", a->undermine_mm,
                  "free the tissue from the bone within this distance of the wound (mm), as a surgeon undermines; 0 = only the sutured columns (the paper)")
      ->capture_default_str();
  cmd->add_option("--rim", a->rim, "outer rim: fixed (clamped) or free (traction free)")
      ->capture_default_str();
  cmd->add_option("--grading", a->grading, "thickness ratio of each layer to the one above")
      ->capture_default_str();
  cmd->add_option("--t1", a->t1_deg, "stage 1: fill concave corners deeper than this (deg)")
      ->capture_default_str();
  cmd->add_option("--stage1-angle", a->stage1_angle_deg,
                  "stage 1: re-triangulate regions of stage-1 triangles with corners below this "
                  "(deg, at most 20.7) with interior points; 0 = the paper's triangles")
      ->capture_default_str();
  cmd->add_option("--t2", a->t2_deg, "stage 2: expand corners sharper than this (deg)")
      ->capture_default_str();
  cmd->add_option("--constant-thickness", a->constant_mm,
                  "mesh a constant depth (mm) instead of the model's thickness (the 1992 paper)");
  cmd->add_flag("--no-pictures", a->no_pictures, "skip surface.png and section.png");
  add_common_flags(cmd, common, true);
  cmd->callback([&common, &action, a] { action = [&common, a] { run_mesh(*a, common); }; });

  auto b = std::make_shared<MeshArgs>();
  auto* sim = app.add_subcommand(
      "simulate", "Mesh a plan on a patient model and solve the wound closure in one go: the "
                  "mesh and result files of caps mesh and caps solve in one folder.\n"
                  "Example: caps simulate --model cranium --plan zplasty.json -o result");
  sim->add_option("--model", b->model, "patient model directory")->required();
  sim->add_option("--plan", b->plan, "the plan (caps plan new)")->required();
  sim->add_option("-o,--output", b->output, "result directory to create")->required();
  sim->add_option("--layers", b->layers, "element layers from skin to bone")->capture_default_str();
  sim->add_option("--size", b->size_mm, "mesh size at the wound (mm)")->capture_default_str();
  sim->add_option("--extent", b->extent_mm, "distance from the wound to the rim (mm); 0 = 3 x wound");
  sim->add_option("--undermine", b->undermine_mm,
                  "free the tissue from the bone within this distance of the wound (mm), as a surgeon undermines; 0 = only the sutured columns (the paper)")
      ->capture_default_str();
  sim->add_option("--rim", b->rim, "outer rim: fixed or free")->capture_default_str();
  sim->add_option("--constant-thickness", b->constant_mm,
                  "a constant depth (mm) instead of the model's thickness (the 1992 paper)");
  sim->add_option("--solver", b->solver, "mumps or cholmod")->capture_default_str();
  sim->add_option("--precision", b->precision,
                  "mixed (a single-precision factorization refined to double accuracy; falls back to double by itself when that is not enough) or double; MUMPS only")
      ->capture_default_str();
  auto* render = sim->add_flag("--render", b->render, "also render pre_<view>.png and post_<view>.png (front, "
                                       "oblique, side, plan; the same camera before and after)");
  sim->add_flag("--tension-map", b->tension_map,
                "with --render, also tension_<view>.png: the skin coloured by its tension (max "
                "principal stress, kPa; the scale tops at the 99th percentile)")
      ->needs(render);
  add_common_flags(sim, common, true);
  sim->callback([&common, &action, b] { action = [&common, b] { run_simulate(*b, common); }; });
}

}  // namespace caps::cli

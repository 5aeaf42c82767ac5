#include "caps/closure/simulate.hpp"

#include <algorithm>
#include <cmath>
#include <set>

#include "caps/core/error.hpp"
#include "caps/fem/inp_io.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/mesher/mesh_pictures.hpp"
#include "caps/fem/result_io.hpp"
#include "caps/plan/check.hpp"
#include "caps/surface/landmarks.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps::closure {

using namespace caps::fem;
using namespace caps::mesher;
namespace {

// The prestressed skin cut and left open: the largest widening (mm) between sutured nodes.
double gape(const Mesh& mesh, SolveOptions options) {
  Mesh open = mesh;
  open.sutures.clear();
  options.reporter = nullptr;
  const SolveResult r = solve(open, options);
  double widest = 0;
  for (const auto& s : mesh.sutures) {
    const Eigen::Vector3d d0 = (mesh.nodes.row(s.b) - mesh.nodes.row(s.a)).transpose();
    const Eigen::Vector3d d = d0 + (r.displacement_mm.row(s.b) - r.displacement_mm.row(s.a)).transpose();
    widest = std::max(widest, d.norm() - d0.norm());
  }
  return widest;
}

// One material for all the soft tissue (the 1992 model, `--tissue uniform`) where the CT measured
// a thick fat layer under the wound: the fat is modelled as stiff as the dermis and the closure's
// forces are overstated (on Cranium's cheek below the eye 3.77 N against 0.94 N with the
// measured layers; docs/fem.md, "The whole face"). The warning, or empty.
std::string uniform_over_fat(const PatientModel& model, const SurfaceMesh& wound,
                             const SimulateOptions& options) {
  const auto& maps = model.maps();
  if (options.continuum.tissue != TissueLayers::Uniform || options.continuum.constant_thickness_mm > 0 ||
      !maps.has_layers() || maps.thickness_fat_normal.empty())
    return {};
  const double fat = model.sample(maps.thickness_fat_normal, wound.theta_c_deg, wound.z_c_mm);
  const double all = model.thickness_normal(wound.theta_c_deg, wound.z_c_mm);
  if (!(fat >= kThickFatMm && fat >= 0.4 * all)) return {};
  const auto mm = [](double x) { return std::round(10 * x) / 10; };
  return cat("the CT measured ", mm(fat), " mm of fat in the ", mm(all),
             " mm of soft tissue under the wound; one material (--tissue uniform, the default) "
             "makes it as stiff as the dermis and overstates the closure's forces (several times "
             "on a thick cheek): --tissue auto models the measured dermis, fat and deep tissue");
}

// The soft tissue the CT measured under the wound's centre where it cannot be a layer over bone
// (surface/landmarks.hpp, tissue_doubt(): the nose's cartilage, the orbit, a cavity): the
// closure meshes it as tissue all the same, so its result says so. The warning, or empty.
std::string implausible_tissue(const PatientModel& model, const SurfaceMesh& wound,
                               const SimulateOptions& options) {
  if (options.continuum.constant_thickness_mm > 0) return {};
  const auto& maps = model.maps();
  const double skin = maps.has_layers() && !maps.thickness_skin_normal.empty()
                          ? model.sample(maps.thickness_skin_normal, wound.theta_c_deg, wound.z_c_mm)
                          : NAN;
  const std::string doubt =
      tissue_doubt(model.thickness_normal(wound.theta_c_deg, wound.z_c_mm), skin);
  if (doubt.empty()) return {};
  return cat("under the wound's centre the CT measured ", doubt, "; the closure meshes it as "
             "soft tissue over bone all the same, so its forces there are not the skin's");
}

// The first layer material CalculiX has no form of under the solve's kinematics (mesh.inp:
// *ELASTIC of the small-strain constants, or NEO HOOKE), or null.
const Material* without_calculix_form(const Mesh& mesh, const SimulateOptions& options) {
  const bool finite = options.solve.kinematics == Kinematics::Finite;
  for (const auto& [layer, m] : mesh.materials)
    if (!m->small_strain() || (finite && m->name() != "neo-hookean")) return m.get();
  return nullptr;
}

// What the closure does to the patient's feature lines: the displacement on the skin (the
// tissue model's and the patch's skin nodes in the whole face; the patch's alone, which says
// nothing beyond its rim, otherwise). Lines the closure does not reach are left out.
std::vector<FeatureDisplacement> moved_features(const Simulation& sim, const PatientModel& model,
                                                const FeatureLines& lines) {
  const Mesh& mesh = sim.face ? sim.face->mesh : sim.wound.continuum.mesh;
  const Eigen::MatrixX3d& u = sim.face ? sim.face_result.displacement_mm : sim.result.displacement_mm;
  const DisplacementAt field = skin_displacement(mesh, u, sim.wound.continuum.skin_node);
  std::vector<FeatureDisplacement> out;
  for (FeatureDisplacement& f : feature_displacements(
           lines, field, anatomical_frame(model)))
    if (f.found && f.has_value) out.push_back(std::move(f));
  return out;
}

}  // namespace

Simulation simulate(const PatientModel& model, const plan::Plan& plan,
                    const SimulateOptions& options, Reporter* reporter) {
  plan::check_plan(plan, model);
  const bool face = options.domain == Domain::Face;
  if (face && !options.tissue)
    throw InvalidInput("--domain face needs the model's whole-face tissue model: build it with "
                       "`caps model tissue MODEL`, or use --domain patch");
  Simulation sim;
  Progress progress(reporter, "meshing and solving", 2);
  ContinuumMeshOptions continuum = options.continuum;
  if (face) continuum.rim = RimCondition::Tied;
  sim.wound = mesh_wound(plan::wound_border(plan), model, options.surface, continuum, reporter);
  if (face) {
    FaceDomainOptions face_options = options.face;
    if (!face_options.reporter) face_options.reporter = reporter;
    sim.face = join_face_domain(sim.wound, model, *options.tissue, continuum,
                                options.solve.kinematics, face_options);
    for (const std::string& w : sim.face->mesh.warnings)
      if (std::find(sim.wound.continuum.mesh.warnings.begin(),
                    sim.wound.continuum.mesh.warnings.end(), w) == sim.wound.continuum.mesh.warnings.end()) {
        warn(reporter, w);
        sim.wound.continuum.mesh.warnings.push_back(w);
      }
  }
  progress.update(1);
  for (const std::string& w : {uniform_over_fat(model, sim.wound.surface, options),
                                implausible_tissue(model, sim.wound.surface, options)})
    if (!w.empty()) {
      warn(reporter, w);
      sim.wound.continuum.mesh.warnings.push_back(w);
    }
  if (const Material* m = without_calculix_form(sim.wound.continuum.mesh, options))
    sim.wound.continuum.mesh.warnings.push_back(
        cat("mesh.inp is not written: CalculiX has no form of the '", m->name(),
            "' material here (use neo-hookean to cross-check with CalculiX)"));
  if (options.solve.prestretch != 1.0)
    sim.wound.continuum.mesh.warnings.push_back(
        "mesh.inp has no prestretch (CalculiX has no prestrain): it is the closure of unstressed skin");
  SolveOptions solve_options = options.solve;
  if (!solve_options.reporter) solve_options.reporter = reporter;
  if (face) {
    sim.face_result = solve(sim.face->mesh, solve_options);
    sim.result = patch_part(sim.face_result, sim.face->n_patch_nodes, sim.face->n_patch_elements);
  } else {
    sim.result = solve(sim.wound.continuum.mesh, solve_options);
  }
  progress.done();
  // The sutures must close: measured on the deformed positions, not assumed.
  const Mesh& mesh = sim.wound.continuum.mesh;
  const auto& u = sim.result.displacement_mm;
  for (const auto& s : mesh.sutures) {
    const Eigen::Vector3d a = mesh.nodes.row(s.a).transpose() + u.row(s.a).transpose();
    const Eigen::Vector3d b = mesh.nodes.row(s.b).transpose() + u.row(s.b).transpose();
    sim.max_suture_gap_mm = std::max(sim.max_suture_gap_mm, (a - b).norm());
  }
  // Inverted elements: the deformed mesh's Jacobians (a finite-strain solve refuses them).
  const Mesh& solved = face ? sim.face->mesh : mesh;
  Mesh deformed = solved;
  deformed.nodes += face ? sim.face_result.displacement_mm : u;
  const Eigen::VectorXd det = min_element_jacobians(deformed);
  sim.inverted_elements = static_cast<int>((det.array() <= 0).count());
  if (sim.inverted_elements > 0)
    sim.wound.continuum.mesh.warnings.push_back(
        cat("the closure turns ", sim.inverted_elements, " of ", solved.n_elements(),
            " elements inside out: the small-strain (linear) model does not hold for a closure "
            "this large; use --material neo-hookean"));
  sim.sutures = suture_spacing(sim.wound.continuum, sim.result, options.suture_spacing_mm);
  if (solve_options.prestretch != 1.0) sim.gape_mm = gape(solved, solve_options);
  if (options.features) sim.features = moved_features(sim, model, *options.features);
  return sim;
}

void write_simulation(const Simulation& sim, const PatientModel& model,
                      const SimulateOptions& options, const std::filesystem::path& dir,
                      const std::string& name, bool mesh_pictures) {
  // The whole face's mesh and result where it was solved (ParaView and CalculiX see all of it).
  const Mesh& mesh = sim.face ? sim.face->mesh : sim.wound.continuum.mesh;
  write_mesh_dir(mesh, dir);
  InpOptions inp;
  inp.finite_strain = options.solve.kinematics == Kinematics::Finite;
  inp.increments = options.solve.newton.n_steps;
  inp.grow_increments = options.solve.newton.grow_iterations > 0;
  if (!without_calculix_form(mesh, options)) write_inp(mesh, dir / "mesh.inp", inp);
  write_result_dir(mesh, sim.face ? sim.face_result : sim.result, dir, &sim.sutures);
  if (!mesh_pictures) return;
  write_surface_mesh_png(dir / "surface.png", sim.wound.surface, cat("surface mesh of ", name));
  write_cross_section_png(dir / "section.png", sim.wound.surface, model, options.continuum,
                          cat("cross-section of ", name));
}

}  // namespace caps::closure

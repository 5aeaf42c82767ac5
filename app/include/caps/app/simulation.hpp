#pragma once
/// @brief The mesh, solve, simulate, compare and `fem box` verbs as requests and results.
///
/// Every request lists its fields once (see fields.hpp); defaults come from the library's
/// options structs (mesher::SurfaceMeshOptions, mesher::ContinuumMeshOptions, fem::SolveOptions).

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "caps/app/fields.hpp"
#include "caps/core/error.hpp"
#include "caps/core/reporter.hpp"
#include "caps/closure/simulate.hpp"

namespace caps::app {

/// How a wound is meshed (caps mesh, simulate and compare share these).
struct MeshingFields {
  int layers = mesher::ContinuumMeshOptions{}.n_layers;
  double mesh_size = mesher::SurfaceMeshOptions{}.size_mm;
  double extent = mesher::SurfaceMeshOptions{}.extent_mm;
  double undermine = mesher::ContinuumMeshOptions{}.undermine_mm;
  std::string rim = mesher::rim_condition_name(mesher::ContinuumMeshOptions{}.rim);
  std::string base = mesher::base_condition_name(mesher::ContinuumMeshOptions{}.base);
  double grading = mesher::ContinuumMeshOptions{}.grading;
  double t1 = mesher::SurfaceMeshOptions{}.t1_deg;
  double stage1_angle = mesher::SurfaceMeshOptions{}.stage1_min_angle_deg;
  double t2 = mesher::SurfaceMeshOptions{}.t2_deg;
  double constant_thickness = mesher::ContinuumMeshOptions{}.constant_thickness_mm;
  std::string tissue = mesher::tissue_layers_name(mesher::ContinuumMeshOptions{}.tissue);
  std::string wedge_rule = fem::wedge_rule_name(mesher::ContinuumMeshOptions{}.wedge_rule);
  /// The budget checked before meshing (check_mesh_budget()): the wound mesh's elements as
  /// estimated from the wound, the extent, the mesh size and the layers.
  double max_elements = 1e6;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.layers, {"layers", "element layers from skin to bone"});
    v(r.mesh_size, {"mesh_size", "mesh size at the wound and first layer thickness (mm)",
                    FieldKind::Option, {}, "--size"});
    v(r.extent, {"extent", "distance from the wound to the outer rim (mm); 0 = 3 x the wound's size"});
    v(r.undermine, {"undermine", "free the tissue from the bone within this distance of the wound "
                                 "(mm), as a surgeon undermines (default about the excision's width; "
                                 "flaps are freed whole); 0 = only the sutured columns and flaps"});
    v(r.rim, {"rim", "outer rim: fixed (clamped) or free (traction free)"});
    v(r.base, {"base", "undermined tissue and flaps: slide (rest on the deep tissue and slide over "
                       "it) or free (may lift off or sink in: the 1992 model)"});
    v(r.grading, {"grading", "thickness ratio of each layer to the one above"});
    v(r.t1, {"t1", "stage 1: fill concave corners deeper than this (deg)"});
    v(r.stage1_angle, {"stage1_angle", "stage 1: re-triangulate regions of stage-1 triangles with "
                                       "corners below this (deg, at most 20.7) with interior "
                                       "points; 0 = the paper's triangles"});
    v(r.t2, {"t2", "stage 2: expand corners sharper than this (deg)"});
    v(r.constant_thickness, {"constant_thickness", "mesh a constant depth (mm) instead of the "
                                                   "model's thickness (the 1992 paper); 0 = measured"});
    v(r.tissue, {"tissue", "tissue layers: measured (dermis, fat and deep tissue from the model's "
                           "layer maps, each its own material), uniform (one material, the 1992 "
                           "model) or auto (measured where the model has them)"});
    v(r.wedge_rule, {"wedge_rule", "how the wedge elements are integrated: full (21 points, "
                                   "exact on straight wedges) or calculix (CalculiX's 9 points "
                                   "for C3D15: mesh.inp then solves in ccx to the same answer)"});
    v(r.max_elements, {"max_elements", "refuse, before meshing, a wound mesh estimated to have "
                                       "more elements than this (default 1e6)"});
  }
};

/// The wound mesh's element count estimated before meshing: the border loop in the wound's
/// tangent plane (mm, at the model's skin radius at its centre), its perimeter P and size W, the
/// extent E (3 W when 0), the mesh size h and the n element layers: (P E + pi E^2) / h^2 * n
/// (the surface mesher's layers keep at most the border's edge length h out to the extent): an
/// upper bound; measured, the meshes had 1/3 to 1/30 of it (Cranium's three demo plans and the
/// phantom's Z-plasty at h = 0.5, 1 and 2 mm), and it scales with 1/h^2 as they do.
/// Throws InvalidParameter naming {mesh_size} and {max_elements} when above meshing.max_elements.
double check_mesh_budget(const plan::WoundBorder& border, const PatientModel& model,
                         const MeshingFields& meshing);
/// The same for a wound of this size W (its largest extent) and border length P, in mm.
double check_mesh_budget(double wound_size_mm, double perimeter_mm, const MeshingFields& meshing);

/// Which sparse solver (caps solve, simulate and compare share these).
struct SolverFields {
  std::string solver = fem::solver_name(fem::SolveOptions{}.solver);
  std::string precision = fem::SolveOptions{}.mixed_precision ? "mixed" : "double";
  /// The closure's model: finite strain (neo-Hookean) by default, the linear (small-strain)
  /// model of 1992 on request. The small-strain model turns elements inside out under a
  /// Z-plasty's rotations and crushes thin fat (issue 12; docs/fem.md, "The default:
  /// neo-Hookean"); the fem library's own SolveOptions stay linear, the model its verification
  /// tests name.
  std::string material = "neo-hookean";
  /// Per-layer material parameters, "LAYER.NAME=VALUE,..." in the material's declared units
  /// (fem::material_kind(); e.g. "dermis.E=0.12,fat.nu=0.4"): layers skin (the uniform model's
  /// one material), dermis, fat and deep (the measured layers).
  std::string material_params;
  int steps = fem::NewtonOptions{}.n_steps;
  double prestretch = fem::SolveOptions{}.prestretch;
  double time_limit = fem::SolveOptions{}.time_limit_s;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.material, {"material", "neo-hookean (finite strain, sutures closed in load steps by "
                               "Newton-Raphson), linear (small strain, the 1992 model: fast, but "
                               "it inverts elements under large closures) or goh "
                               "(finite strain, skin with collagen fibres along the patient's "
                               "left-right, the forehead's Langer lines; docs/fem.md)"});
    v(r.material_params, {"material_params", "per-layer material parameters LAYER.NAME=VALUE,... "
                                             "(layers skin, dermis, fat, deep); a modulus takes "
                                             "its unit, kPa or MPa (a bare number is MPa, refused "
                                             "above 10), e.g. dermis.E=120kPa,fat.nu=0.4 "
                                             "(docs/fem.md, \"Materials\")"});
    v(r.steps, {"steps", "neo-hookean: the first load step closes 1/steps of the sutures' gap; "
                         "a step that converges easily doubles the next, one that does not "
                         "converge is cut back (without cut-backs at most this many steps)"});
    v(r.prestretch, {"prestretch", "neo-hookean: the skin's in-vivo prestretch in its plane (1 = "
                                   "none; about 1.1-1.2 in vivo): the wound gapes, and the "
                                   "closure and its forces carry the skin's tension"});
    v(r.time_limit, {"time_limit", "neo-hookean: stop a closure still unsolved after this many "
                                   "seconds, with an error saying how far it came (the linear "
                                   "model answers in one solve); 0 = no limit. Newton stops by "
                                   "itself after 400 solves or 200 load steps"});
    v(r.solver, {"solver", "auto (MUMPS; CHOLMOD for a finite-strain closure in the whole "
                           "face), mumps or cholmod"});
    v(r.precision, {"precision", "mixed (a single-precision factorization refined to double "
                                 "accuracy; falls back to double by itself when that is not "
                                 "enough) or double; MUMPS only"});
  }
};

/// Where the closure is solved (caps simulate and compare, the planner, Python, the cohort).
struct DomainFields {
  std::string domain = "face";
  double face_radius = closure::FaceDomainOptions{}.radius_mm;
  std::string tie = fem::tie_method_name(closure::FaceDomainOptions{}.tie);

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.domain, {"domain", "face: the wound's patch tied into the patient's whole-face tissue "
                           "model (built by caps model from-volume or caps model tissue), "
                           "attached to the bone, free at the eyelids, lips and nostrils; "
                           "patch: the 1992 patch clamped at its rim (docs/fem.md, \"The whole "
                           "face\")"});
    v(r.face_radius, {"face_radius", "--domain face: the tissue model is kept within this "
                                     "distance of the wound (mm) and held beyond; 0 = automatic "
                                     "(5 mm beyond the patch's rim, at least 40 mm)"});
    v(r.tie, {"tie", "--domain face: how the patch's rim is tied to the tissue: mortar (exact "
                     "for a uniform stress across the join) or node-to-surface (CalculiX's "
                     "*TIE: a mesh.inp that ccx solves in seconds, for cross-checks; it takes the mortar "
                     "rows' equations many minutes to read)"});
  }
};

/// Sets `o` to solve in the domain `d` and reads the model directory's feature lines; for face,
/// its whole-face tissue model. A model without one (a local chart, a scan-built model, one made
/// before it existed) is solved on the clamped patch: the returned warning says so (empty
/// otherwise), for the caller to carry into the result.
std::string set_domain(closure::SimulateOptions& o, const DomainFields& d,
                       const std::string& model_dir);

/// The library options of the meshing and solver fields (names checked, InvalidInput naming
/// the option otherwise).
closure::SimulateOptions simulate_options(const MeshingFields& meshing, const SolverFields& solver);

// ---- caps mesh ----------------------------------------------------------------------------

struct MeshRequest {
  std::string model, plan, border, output;
  MeshingFields meshing;
  bool no_pictures = false;
  bool force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "patient model directory", FieldKind::Required});
    v(r.plan, {"plan", "the plan (caps plan new)"});
    v(r.border, {"border", "or a bare wound border JSON: {\"loop_theta_z\": [[deg, mm], ...], "
                           "\"sutures\": [[a, b, c, d], ...]}"});
    v(r.output, {"output", "mesh directory to create", FieldKind::Required, "-o,--output"});
    MeshingFields::fields(r.meshing, v);
    v(r.no_pictures, {"no_pictures", "skip surface.png and section.png", FieldKind::Flag});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

struct MeshResult {
  std::string output;
  int surface_vertices = 0, quads = 0, triangles = 0, surface_layers = 0;
  /// Surface polygons left out where they reached cells the model cannot carry (0: a whole mesh;
  /// mesher::SurfaceMesh::trimmed_polygons).
  int trimmed_polygons = 0;
  double extent_mm = 0, wound_size_mm = 0, min_angle_deg = 0, max_angle_deg = 0;
  double max_aspect_ratio = 0, mean_aspect_ratio = 0;
  int nodes = 0, elements = 0, hex20 = 0, wedge15 = 0, layers = 0, fixed_nodes = 0,
      suture_pairs = 0;
  std::string rim;
  std::string tissue;  ///< the tissue layering used: uniform or measured
  double min_thickness_mm = 0, max_thickness_mm = 0, min_jacobian = 0;
  std::vector<std::string> warnings;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.output, {"output", "the mesh directory written"});
    v.group({"surface", "the surface mesh (stage 1 and 2)"}, [&] {
      v(r.surface_vertices, {"vertices"});
      v(r.quads, {"quads"});
      v(r.triangles, {"triangles"});
      v(r.surface_layers, {"layers"});
      v(r.extent_mm, {"extent_mm"});
      v(r.wound_size_mm, {"wound_size_mm"});
      v(r.trimmed_polygons, {"trimmed_polygons"});
      v(r.min_angle_deg, {"min_angle_deg"});
      v(r.max_angle_deg, {"max_angle_deg"});
      v(r.max_aspect_ratio, {"max_aspect_ratio"});
      v(r.mean_aspect_ratio, {"mean_aspect_ratio"});
    });
    v.group({"continuum", "the volume mesh"}, [&] {
      v(r.nodes, {"nodes"});
      v(r.elements, {"elements"});
      v(r.hex20, {"hex20"});
      v(r.wedge15, {"wedge15"});
      v(r.layers, {"layers"});
      v(r.fixed_nodes, {"fixed_nodes"});
      v(r.suture_pairs, {"suture_pairs"});
      v(r.rim, {"rim"});
      v(r.tissue, {"tissue"});
      v.pair(r.min_thickness_mm, r.max_thickness_mm, {"thickness_mm", "least and greatest"});
      v(r.min_jacobian, {"min_jacobian"});
    });
    v(r.warnings, {"warnings"});
  }
};

/// Meshes the plan's (or border's) wound on the model into `output` (see docs/mesh-format.md):
/// mesh.vtu, mesh.json, mesh.inp, surface.png, section.png, summary.json (= to_json(result)).
MeshResult run_mesh(const MeshRequest& request, Reporter* reporter = nullptr);
std::string to_json(const MeshResult& result);
std::string summary(const MeshResult& result);

// ---- caps simulate ------------------------------------------------------------------------

struct SimulateRequest {
  std::string model, plan, output;
  MeshingFields meshing;
  SolverFields solver;
  DomainFields domain;
  double suture_spacing = closure::SimulateOptions{}.suture_spacing_mm;
  bool render = false, tension_map = false;
  bool no_mesh_pictures = false;
  bool force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "patient model directory", FieldKind::Required});
    v(r.plan, {"plan", "the plan (caps plan new)", FieldKind::Required});
    v(r.output, {"output", "result directory to create", FieldKind::Required, "-o,--output"});
    MeshingFields::fields(r.meshing, v);
    SolverFields::fields(r.solver, v);
    DomainFields::fields(r.domain, v);
    v(r.suture_spacing, {"suture_spacing", "report the closing force per suture with sutures this "
                                           "far apart along the wound (mm)"});
    v(r.no_mesh_pictures, {"no_mesh_pictures", "leave out surface.png and section.png, the "
                                               "meshing pictures (the planner's first answer "
                                               "does: they take about a tenth of a small "
                                               "closure's time)", FieldKind::Flag});
    v(r.render, {"render", "also render pre_<view>.png and post_<view>.png (front, oblique, "
                           "side, plan; the same camera before and after)", FieldKind::Flag});
    v(r.tension_map, {"tension_map", "with --render, also tension_<view>.png: the skin coloured "
                                     "by its tension (max principal stress, kPa; the scale tops "
                                     "at the 99th percentile)", FieldKind::Flag});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

/// The wound's length along a plan's axis, before and after closure.
struct AxisLengthening {
  double before_mm = 0, after_mm = 0;
  double change_mm() const { return after_mm - before_mm; }
  double change_percent() const { return before_mm > 0 ? 100.0 * (after_mm / before_mm - 1) : 0; }
};

struct SimulateResult {
  std::string output;
  int elements = 0, nodes = 0, suture_pairs = 0;
  double max_displacement_mm = 0, closing_force_n = 0, max_suture_force_n = 0,
         max_suture_gap_mm = 0, strain_energy_mj = 0;
  std::string material;             ///< the skin's material: linear, neo-hookean or goh
  double prestretch = 1;            ///< the skin's in-plane prestretch (1 = none)
  double gape_mm = 0;               ///< with prestretch: the open wound's largest widening
  int load_steps = 0, newton_iterations = 0;  ///< neo-hookean: converged steps, iterations
  int inverted_elements = 0;        ///< elements the closure turned inside out (linear only)
  /// Surgeons' terms (closure::suture_spacing()): sutures every suture_spacing_mm along the wound,
  /// how many, the largest single-suture force, the force per mm of wound, the wound's length.
  double suture_spacing_mm = 0, max_force_per_suture_n = 0, force_per_mm_n = 0,
         wound_length_mm = 0;
  int sutures = 0;
  /// The tensile sutures' total; the sutures whose pairs push in sum (reported apart, in no
  /// total) and their sum (<= 0), N. The two add up to closing_force_n, the net force.
  double sutures_total_force_n = 0, compressive_force_n = 0;
  int compressive_sutures = 0;
  /// The headline lengthening (corner_lengthening()): the distance between the wound's two
  /// closed corners farthest apart (loop nodes corner_a, corner_b), before and after closure, mm;
  /// a Z-plasty's central limb, corner to corner: its gain as surgeons measure it. Without two
  /// closed corners (corner_a < 0) the axis projection below.
  double corner_length_before_mm = 0, corner_length_after_mm = 0;
  int corner_a = -1, corner_b = -1;
  /// The wound's length projected on the plan's axis before and after closure
  /// (axis_lengthening(): `lengthening.axis_projection`; not the gain), mm.
  double axis_length_before_mm = 0, axis_length_after_mm = 0;
  std::vector<std::string> images;  ///< with render
  std::vector<std::string> warnings;
  double solve_s = 0;  ///< the solver's wall time (not reproducible: under "timings_s")
  /// Where it was solved (closure::Domain) and, for the whole face, what the join did.
  std::string domain = "patch";
  double face_radius_mm = 0, max_tie_distance_mm = 0;
  int face_tets = 0, tied_nodes = 0, untied_nodes = 0, attached_nodes = 0, held_nodes = 0;
  int patch_nodes = 0, patch_elements = 0;
  std::vector<std::string> face_notes;  ///< what the join did, in words
  /// The feature lines the closure moves (closure::Simulation::features), as JSON.
  std::string features_json = "[]";
  std::vector<std::string> feature_sentences;  ///< one per line moved, for the summary

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.output, {"output", "the result directory written"});
    v(r.elements, {"elements"});
    v(r.nodes, {"nodes"});
    v(r.suture_pairs, {"suture_pairs"});
    v(r.max_displacement_mm, {"max_displacement_mm"});
    v(r.closing_force_n, {"closing_force_n", "the sum of the suture pairs' forces (N)"});
    v(r.max_suture_force_n, {"max_suture_force_n", "the largest force on one suture pair (N)"});
    v(r.max_suture_gap_mm, {"max_suture_gap_mm"});
    v.group({"sutures_at_spacing", "the closing force per suture, sutures every spacing_mm"}, [&] {
      v(r.suture_spacing_mm, {"spacing_mm"});
      v(r.sutures, {"sutures"});
      v(r.max_force_per_suture_n, {"max_force_per_suture_n"});
      v(r.force_per_mm_n, {"force_per_mm_n"});
      v(r.wound_length_mm, {"wound_length_mm"});
      v(r.sutures_total_force_n, {"total_force_n", "the pulling sutures' forces added (N)"});
      v(r.compressive_sutures, {"compressive_sutures", "sutures whose pairs push in sum"});
      v(r.compressive_force_n, {"compressive_force_n", "their forces added (N, <= 0)"});
    });
    v(r.strain_energy_mj, {"strain_energy_mj"});
    v.group({"lengthening", "the gain: the distance between the wound's two closed corners "
                            "(corner_lengthening()), else the axis projection"}, [&] {
      v.computed({"between"}, [&] {
        return r.corner_a >= 0 ? cat("closed corners ", r.corner_a, " and ", r.corner_b)
                               : std::string("the wound's ends along the plan's axis");
      });
      v.pair(r.corner_a, r.corner_b, {"corners", "the two closed corners' loop nodes (-1: none)"});
      v(r.corner_length_before_mm, {"before_mm"});
      v(r.corner_length_after_mm, {"after_mm"});
      v.computed({"mm"}, [&] { return r.corner_length_after_mm - r.corner_length_before_mm; });
      v.computed({"percent"}, [&] {
        return AxisLengthening{r.corner_length_before_mm, r.corner_length_after_mm}.change_percent();
      });
      v.group({"axis_projection", "the wound's length projected on the plan's axis "
                                  "(axis_lengthening()): not the gain"}, [&] {
        v(r.axis_length_before_mm, {"before_mm"});
        v(r.axis_length_after_mm, {"after_mm"});
        v.computed({"mm"}, [&] { return r.axis_length_after_mm - r.axis_length_before_mm; });
        v.computed({"percent"}, [&] {
          return AxisLengthening{r.axis_length_before_mm, r.axis_length_after_mm}.change_percent();
        });
      });
    });
    v.group({"domain", "where the closure was solved (--domain)"}, [&] {
      v(r.domain, {"name", "face (the patch tied into the whole-face model) or patch (clamped)"});
      v(r.patch_nodes, {"patch_nodes"});
      v(r.patch_elements, {"patch_elements"});
      v.when(r.domain == "face", [&] {
        v(r.face_radius_mm, {"radius_mm", "the tissue model kept within this distance of the wound"});
        v(r.face_tets, {"tetrahedra"});
        v(r.tied_nodes, {"tied_nodes", "the patch's rim nodes tied to the tetrahedra"});
        v(r.untied_nodes, {"untied_nodes"});
        v(r.max_tie_distance_mm, {"max_tie_distance_mm"});
        v(r.attached_nodes, {"attached_nodes", "tissue nodes on the bone"});
        v(r.held_nodes, {"held_nodes", "tissue nodes where the region or the CT ends"});
        v(r.face_notes, {"notes"});
      });
    });
    v.json_value(r.features_json, {"features", "each feature line's displacement by the closure "
                                               "(mm, with direction, place and warning)"});
    v(r.feature_sentences, {"feature_sentences"});
    v(r.material, {"material"});
    v(r.prestretch, {"prestretch"});
    v(r.gape_mm, {"gape_mm"});
    v(r.load_steps, {"load_steps"});
    v(r.newton_iterations, {"newton_iterations"});
    v(r.inverted_elements, {"inverted_elements"});
    v(r.images, {"images"});
    v(r.warnings, {"warnings"});
    v.group({"timings_s", "wall-clock seconds (not reproducible)"},
            [&] { v(r.solve_s, {"solve"}); });
  }
};

/// The length of a wound's border along the plan's axis: its loop nodes projected on `axis`
/// (unit, LPS), the ends being the nodes of least and greatest projection before closure
/// (coincident nodes, the two lips of a cut, within 1e-6 of the extent all count); before: the
/// distance between the two ends' projections, after: between the last of the far end's nodes
/// and the first of the near end's, displaced. For a Z-plasty (axis along the central limb) the
/// ends are the limb's two points, each on both lips: after the closure its closed corners
/// (loop 5 and 2) mark the lengthened limb, the flap tips (1 and 4, swung across) do not count.
/// @param pre   #L×3 loop node positions before closure (LPS mm)
/// @param post  #L×3 the same nodes after closure (LPS mm)
AxisLengthening axis_lengthening(const Eigen::MatrixX3d& pre, const Eigen::MatrixX3d& post,
                                 const Eigen::Vector3d& axis);

/// The distance between a wound's two closed corners farthest apart, before and after closure:
/// the corners are the loop nodes both runs of a suture share (a == c or b == d of the
/// mesher::WoundBorder quadruples (a, b, c, d)). A Z-plasty has two, the ends of its central limb
/// on the lips that stay (loop 5 and 2; the flap tips 1 and 4 swing across), so this is its
/// central limb's length corner to corner, and the change its gain (a 60 deg Z with rigid flaps:
/// sqrt(5 - 4 cos 60) - 1 = 73 %); a multiple Z's, its whole central line's. Returns before =
/// after = 0 and corners -1 without two corners.
/// @param pre   #L×3 loop node positions before closure (LPS mm)
/// @param post  #L×3 the same nodes after closure (LPS mm)
struct CornerLengthening {
  double before_mm = 0, after_mm = 0;
  int corner_a = -1, corner_b = -1;  ///< loop nodes, corner_a < corner_b
};
CornerLengthening corner_lengthening(const Eigen::MatrixX3d& pre, const Eigen::MatrixX3d& post,
                                     const std::vector<std::array<int, 4>>& sutures);

/// A closure's figures as caps simulate reports them (everything but `output` and `images`).
SimulateResult simulation_summary(const closure::Simulation& sim,
                                  const closure::SimulateOptions& options, const plan::Plan& plan,
                                  const PatientModel& model);

/// Writes a closure into `dir` as caps simulate does (closure::write_simulation(), the meshes
/// naming `model_dir` and `plan_path`, and the plan as plan.json beside them; not summary.json)
/// and returns its summary (simulation_summary()).
SimulateResult write_closure(closure::Simulation& sim, const closure::SimulateOptions& options,
                             const plan::Plan& plan, const std::string& plan_path,
                             const PatientModel& model, const std::string& model_dir,
                             const std::filesystem::path& dir, bool mesh_pictures);

/// Meshes the plan on the model and solves the closure into `output`: the files of caps mesh
/// and caps solve (result.json carries the warnings), and with `render` the images.
SimulateResult run_simulate(const SimulateRequest& request, Reporter* reporter = nullptr);
std::string to_json(const SimulateResult& result);
std::string summary(const SimulateResult& result);

// ---- caps solve ---------------------------------------------------------------------------

struct SolveRequest {
  std::string mesh, output;
  SolverFields solver;
  std::optional<double> E;   ///< kPa, every layer
  std::optional<double> nu;  ///< every layer
  bool force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.mesh, {"mesh", "mesh directory (mesh.json + mesh.vtu)", FieldKind::Positional, "MESH_DIR"});
    v(r.output, {"output", "result directory to create", FieldKind::Required, "-o,--output"});
    SolverFields::fields(r.solver, v);
    v(r.E, {"E", "Young's modulus in kPa for every layer (overrides mesh.json)", FieldKind::Option,
            "--E"});
    v(r.nu, {"nu", "Poisson's ratio for every layer, 0 <= nu <= 0.499"});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

struct SolveResult {
  std::string output, solver;
  int equations = 0;
  double max_displacement_mm = 0, max_von_mises_mpa = 0, total_suture_force_n = 0,
         strain_energy_mj = 0;
  std::vector<std::string> warnings;
  double total_s = 0;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.output, {"output", "the result directory written"});
    v(r.solver, {"solver"});
    v(r.equations, {"equations"});
    v(r.max_displacement_mm, {"max_displacement_mm"});
    v(r.max_von_mises_mpa, {"max_von_mises_mpa"});
    v(r.total_suture_force_n, {"total_suture_force_n"});
    v(r.strain_energy_mj, {"strain_energy_mj"});
    v(r.warnings, {"warnings"});
    v.group({"timings_s", "wall-clock seconds (not reproducible)"},
            [&] { v(r.total_s, {"total"}); });
  }
};

SolveResult run_solve(const SolveRequest& request, Reporter* reporter = nullptr);
std::string to_json(const SolveResult& result);
std::string summary(const SolveResult& result);

// ---- caps fem box -------------------------------------------------------------------------

struct BoxRequest {
  std::string output, box_size = "40,10,10", cells = "8,2,2";
  bool slot = false, wedges = false, force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.output, {"output", "mesh directory to create", FieldKind::Required, "-o,--output"});
    v(r.box_size, {"box_size", "box size in mm along x,y,z", FieldKind::Option, {}, "--size"});
    v(r.cells, {"cells", "cells along x,y,z"});
    v(r.slot, {"slot", "cut a slot through the middle x column and suture it", FieldKind::Flag});
    v(r.wedges, {"wedges", "split every cell into two Wedge15", FieldKind::Flag});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

struct BoxResult {
  std::string output;
  int nodes = 0, elements = 0, sutures = 0;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.output, {"output", "the mesh directory written"});
    v(r.nodes, {"nodes"});
    v(r.elements, {"elements"});
    v(r.sutures, {"sutures", "suture pairs"});
  }
};

BoxResult run_box(const BoxRequest& request, Reporter* reporter = nullptr);
std::string to_json(const BoxResult& result);
std::string summary(const BoxResult& result);

// ---- caps compare -------------------------------------------------------------------------

struct CompareRequest {
  std::string model, plan, output;
  double thickness = 0;
  MeshingFields meshing;
  SolverFields solver;
  /// The whole face by default, as simulate: the three closures differ only in the tissue under
  /// the wound's patch (the constant thickness, or the measured layers), and the CT's tissue
  /// around it is the same in all three, so no clamped rim decides the comparison. `patch`:
  /// the 1992 clamped patch, where the constant thickness is the whole model's.
  DomainFields domain;
  bool force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "patient model directory (from a volume)", FieldKind::Required});
    v(r.plan, {"plan", "the plan (caps plan new)", FieldKind::Required});
    v(r.output, {"output", "the folder to create", FieldKind::Required, "-o,--output"});
    v(r.thickness, {"thickness", "the constant thickness in mm (0: the median measured under the "
                                 "wound)"});
    MeshingFields::fields(r.meshing, v);
    SolverFields::fields(r.solver, v);
    DomainFields::fields(r.domain, v);
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

struct CompareResult {
  std::string output;
  std::string comparison_json;  ///< comparison.json (the table, warnings included)
  double measured_closing_force_n = 0, constant_closing_force_n = 0;
  double measured_max_displacement_mm = 0, constant_max_displacement_mm = 0;
  /// The third column: the measured thickness in the measured tissue layers.
  double layers_closing_force_n = 0, layers_max_displacement_mm = 0;
  std::string layers_tissue;  ///< "measured", or "uniform" where the model has no layers
  double constant_thickness_mm = 0;
  std::vector<std::string> warnings;
  std::string domain = "face";  ///< where the three closures were solved (--domain)

  /// The JSON is comparison.json (the table, warnings included) and the output folder.
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v.document(r.comparison_json, {"comparison_json", "comparison.json"});
    v(r.output, {"output", "the folder written"});
  }
};

/// Simulates the plan with the measured and with a constant thickness (one material), and with
/// the measured thickness in the measured tissue layers, and writes measured/, constant/,
/// comparison.json (all three columns) and report.html (the first two) into `output`.
CompareResult run_compare(const CompareRequest& request, Reporter* reporter = nullptr);
std::string to_json(const CompareResult& result);
std::string summary(const CompareResult& result);

}  // namespace caps::app

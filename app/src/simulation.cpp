#include "caps/app/simulation.hpp"

#include "caps/mesher/tissue_model.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/json_limits.hpp"
#include "caps/fem/box.hpp"
#include "caps/fem/elements.hpp"
#include "caps/study/compare.hpp"
#include "caps/fem/inp_io.hpp"
#include "caps/fem/material_registry.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/mesher/mesh_pictures.hpp"
#include "caps/fem/result_io.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/render/drawn_skin.hpp"
#include "caps/render/simulation_report.hpp"
#include "caps/app/loaded_model.hpp"
#include "model_result.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/volume/model_dir.hpp"
#include "json_fields.hpp"
#include "numbers.hpp"
#include "output_check.hpp"
#include "skin_place.hpp"

CAPS_APP_REQUEST_JSON(caps::app::MeshRequest)
CAPS_APP_REQUEST_JSON(caps::app::SimulateRequest)
CAPS_APP_REQUEST_JSON(caps::app::SolveRequest)
CAPS_APP_REQUEST_JSON(caps::app::BoxRequest)
CAPS_APP_REQUEST_JSON(caps::app::CompareRequest)
CAPS_APP_RESULT_JSON(caps::app::MeshResult)
CAPS_APP_RESULT_JSON(caps::app::SimulateResult)
CAPS_APP_RESULT_JSON(caps::app::SolveResult)
CAPS_APP_RESULT_JSON(caps::app::BoxResult)
CAPS_APP_RESULT_JSON(caps::app::CompareResult)

namespace caps::app {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// "LAYER.NAME=VALUE,..." (SolverFields::material_params) -> layer -> parameter changes.
std::map<std::string, fem::MaterialParameters> parse_material_params(const std::string& text) {
  std::map<std::string, fem::MaterialParameters> out;
  std::stringstream items(text);
  std::string item;
  while (std::getline(items, item, ',')) {
    item.erase(0, item.find_first_not_of(" \t"));
    item.erase(item.find_last_not_of(" \t") + 1);
    if (item.empty()) continue;
    const std::size_t dot = item.find('.'), eq = item.find('=');
    double value = NAN;
    std::string unit;  // "kPa" or "MPa" when the value says it; none: the declared unit
    if (eq != std::string::npos) {
      std::string text = item.substr(eq + 1);
      for (const char* u : {"kPa", "MPa"})
        if (text.size() > 3 && text.compare(text.size() - 3, 3, u) == 0) {
          unit = u;
          text.resize(text.size() - 3);
        }
      std::istringstream in(text);
      if (!(in >> value) || !in.eof()) value = NAN;
    }
    if (dot == std::string::npos || eq == std::string::npos || eq < dot || dot == 0 ||
        eq == dot + 1 || !std::isfinite(value))
      throw InvalidParameter(cat("{material_params} '", item, "': give LAYER.NAME=VALUE items "
                                 "separated by commas, e.g. dermis.E=120kPa,fat.nu=0.4"));
    // Moduli are declared in MPa; a surgeon thinks of soft tissue in kPa. A bare modulus above
    // kMaxBareModulusMpa (soft tissue is 0.001-1 MPa, collagen fibres' k1 about 5 MPa) is most
    // likely kPa typed as MPa: the unit must then be written.
    constexpr double kMaxBareModulusMpa = 10;
    if (unit == "kPa") value *= 1e-3;
    if (unit.empty() && std::abs(value) > kMaxBareModulusMpa)
      throw InvalidParameter(cat("{material_params} '", item, "': ", value, " MPa is far stiffer "
                                 "than soft tissue (0.001-1 MPa); write the unit: ",
                                 item.substr(0, eq), "=", value, "kPa, or ", item.substr(0, eq),
                                 "=", value, "MPa if you mean it"));
    const std::string layer = item.substr(0, dot);
    if (layer != "skin" && layer != "dermis" && layer != "fat" && layer != "deep")
      throw InvalidParameter(cat("{material_params} '", item, "': the layers are skin (the uniform "
                                 "model's one material), dermis, fat and deep"));
    out[layer][item.substr(dot + 1, eq - dot - 1)] = value;
  }
  return out;
}

// A material made from an option's values: its InvalidInput (which names the option in braces)
// becomes an InvalidParameter, so that each front end spells the option its own way.
template <class F>
std::shared_ptr<const fem::Material> from_option(F&& make) {
  try {
    return make();
  } catch (const InvalidParameter&) {
    throw;
  } catch (const InvalidInput& e) {
    throw InvalidParameter(e.what());
  }
}

// The material kind --material gives the layers: linear and neo-hookean keep each layer's
// parameters (E, nu); goh (the preset porcine skin, fibres along the patient's left-right) is
// the skin's surface layer's alone (mesher::ContinuumMeshOptions::surface_material), the others
// keep theirs.
std::shared_ptr<const fem::Material> as_chosen(const std::shared_ptr<const fem::Material>& m,
                                               const std::string& material, bool surface) {
  if (material == "goh") return surface ? fem::default_goh_skin() : m;
  if (m->name() == material) return m;
  return from_option([&] { return fem::make_material(material, fem::parameters_of(*m), cat("{material} ", material)); });
}

void check_material(const std::string& material) {
  if (material != "goh" && material != "linear" && material != "neo-hookean")
    throw InvalidParameter(cat("{material} '", material, "' is unknown: use neo-hookean (finite "
                               "strain, the default), linear (small strain, the 1992 model) or "
                               "goh (finite strain, skin with collagen fibres)"));
}

void set_materials(closure::SimulateOptions& o, const SolverFields& s) {
  check_material(s.material);
  o.solve.kinematics = s.material == "linear" ? fem::Kinematics::Linear : fem::Kinematics::Finite;
  auto& c = o.continuum;
  for (auto* m : {&c.material, &c.dermis, &c.fat, &c.deep}) *m = as_chosen(*m, s.material, false);
  const bool goh = s.material == "goh";
  if (goh) c.surface_material = fem::default_goh_skin();
  for (const auto& item : parse_material_params(s.material_params)) {
    // (No structured bindings: clang 14 cannot capture them in the lambda below.)
    const std::string& layer = item.first;
    const auto& changes = item.second;
    // With goh, skin and dermis name the goh surface layer.
    auto& m = goh && (layer == "skin" || layer == "dermis") ? c.surface_material
              : layer == "skin"                             ? c.material
              : layer == "dermis"                           ? c.dermis
              : layer == "fat"                              ? c.fat
                                                            : c.deep;
    m = from_option([&] { return fem::with_parameters(*m, changes, cat("{material_params} ", layer)); });
  }
}

void set_materials(fem::Mesh& mesh, const SolverFields& s) {
  check_material(s.material);
  // A mesh directory's layers: its skin is layer 0 and every layer of the same material (all of
  // a uniform mesh's; with goh, layer 0 alone, the goh layer), dermis, fat and deep are layers
  // 0, 1 and 2 (the measured layers' ids).
  const fem::Material* top = mesh.materials.count(0) ? mesh.materials.at(0).get() : nullptr;
  const std::string top_json = top ? fem::material_json(*top) : std::string();
  std::map<int, bool> skin;
  for (const auto& [layer, m] : mesh.materials)
    skin[layer] = layer == 0 || (s.material != "goh" && top && fem::material_json(*m) == top_json);
  for (auto& [layer, m] : mesh.materials) m = as_chosen(m, s.material, layer == 0);
  for (const auto& item : parse_material_params(s.material_params)) {
    const std::string& name = item.first;  // (clang 14 cannot capture structured bindings)
    const auto& changes = item.second;
    for (auto& entry : mesh.materials) {
      const int layer = entry.first;
      auto& m = entry.second;
      if (name == "skin" ? skin[layer] : layer == (name == "dermis" ? 0 : name == "fat" ? 1 : 2))
        m = from_option([&] { return fem::with_parameters(*m, changes, cat("{material_params} ", name)); });
    }
  }
}

}  // namespace

closure::SimulateOptions simulate_options(const MeshingFields& m, const SolverFields& s) {
  if (!(m.mesh_size > 0) || !std::isfinite(m.mesh_size))
    throw InvalidParameter(cat("{mesh_size} ", m.mesh_size, ": give the mesh size in mm, > 0 "
                               "(e.g. 2)"));
  if (!(m.max_elements >= 1) || std::isnan(m.max_elements))
    throw InvalidParameter(cat("{max_elements} ", m.max_elements, ": give a positive number of "
                               "elements"));
  closure::SimulateOptions o;
  o.surface.size_mm = m.mesh_size;
  o.surface.extent_mm = m.extent;
  o.surface.t1_deg = m.t1;
  o.surface.stage1_min_angle_deg = m.stage1_angle;
  o.surface.t2_deg = m.t2;
  o.continuum.n_layers = m.layers;
  o.continuum.grading = m.grading;
  o.continuum.rim = mesher::parse_rim_condition(m.rim);
  o.continuum.constant_thickness_mm = m.constant_thickness;
  o.continuum.undermine_mm = m.undermine;
  o.continuum.base = mesher::parse_base_condition(m.base);
  o.continuum.tissue = mesher::parse_tissue_layers(m.tissue);
  o.continuum.wedge_rule = fem::parse_wedge_rule(m.wedge_rule);
  o.solve.solver = fem::parse_solver(s.solver);
  o.solve.mixed_precision = fem::parse_precision(s.precision);
  set_materials(o, s);
  o.solve.prestretch = s.prestretch;
  if (s.steps < 1 || s.steps > 1000)
    throw InvalidParameter(cat("{steps} ", s.steps, ": give 1..1000 load steps"));
  o.solve.newton.n_steps = s.steps;
  if (!(s.time_limit >= 0 && s.time_limit <= 86400))
    throw InvalidParameter(cat("{time_limit} ", s.time_limit, ": give seconds, 0 (no limit) to "
                               "86400"));
  o.solve.time_limit_s = s.time_limit;
  return o;
}

double check_mesh_budget(const plan::WoundBorder& border, const PatientModel& model,
                         const MeshingFields& m) {
  const auto& loop = border.loop_theta_z;
  if (loop.size() < 2) return 0;  // the mesher says what is wrong with the loop
  // The loop unwrapped around its first point, as the surface mesher's tangent plane has it.
  const double t0 = loop[0].x();
  double sx = 0, sz = 0;
  for (const auto& p : loop) {
    sx += std::remainder(p.x() - t0, 360.0);
    sz += p.y();
  }
  const double n = static_cast<double>(loop.size());
  const double theta_c = t0 + sx / n, z_c = sz / n;
  const double radius_mm = model.r_skin(theta_c, z_c);
  if (!(radius_mm > 0) || !std::isfinite(radius_mm)) return 0;  // the mesher refuses it
  std::vector<Eigen::Vector2d> L;
  for (const auto& p : loop)
    L.emplace_back(std::remainder(p.x() - theta_c, 360.0) * M_PI / 180.0 * radius_mm, p.y() - z_c);
  double perimeter_mm = 0, size_mm = 0;
  for (std::size_t i = 0; i < L.size(); ++i) {
    perimeter_mm += (L[(i + 1) % L.size()] - L[i]).norm();
    for (std::size_t j = 0; j < i; ++j) size_mm = std::max(size_mm, (L[j] - L[i]).norm());
  }
  if (!std::isfinite(perimeter_mm)) return 0;
  return check_mesh_budget(size_mm, perimeter_mm, m);
}

double check_mesh_budget(double size_mm, double perimeter_mm, const MeshingFields& m) {
  const double extent_mm = m.extent > 0 ? m.extent : 3.0 * size_mm;
  const double h = m.mesh_size, layers = std::max(1, m.layers);
  const double estimate =
      (perimeter_mm * extent_mm + M_PI * extent_mm * extent_mm) / (h * h) * layers;
  if (!(estimate <= m.max_elements))
    throw InvalidParameter(cat("{mesh_size} ", h, " mm asks for up to about ",
                               round_to(estimate, 0), " elements (a wound of ", round_to(size_mm, 1), " mm with a border "
                               "of ", round_to(perimeter_mm, 1), " mm, meshed ",
                               round_to(extent_mm, 1), " mm around it in ", layers,
                               " layers), more than the limit of ", m.max_elements,
                               " ({max_elements}); give a larger mesh size or a smaller extent, "
                               "or raise the limit"));
  return estimate;
}

std::string set_domain(closure::SimulateOptions& o, const DomainFields& d,
                       const std::string& model_dir) {
  o.domain = closure::parse_domain(d.domain);
  if (!(d.face_radius >= 0) || !std::isfinite(d.face_radius) || d.face_radius > 500)
    throw InvalidParameter(cat("{face_radius} ", d.face_radius, ": give the region's radius in "
                               "mm, 0 (automatic) or up to 500"));
  o.face.radius_mm = d.face_radius;
  o.face.tie = fem::parse_tie_method(d.tie);
  o.features = loaded_feature_lines(model_dir);
  if (o.domain != closure::Domain::Face) return {};
  if (!mesher::has_tissue_model(model_dir)) {
    // A chart's plan is solved in its parent's whole face (the chart's patch is in the parent's
    // frame), and reports the parent's feature lines.
    const std::string parent = detail::chart_parent(model_dir);
    if (!parent.empty() && mesher::has_tissue_model(parent)) {
      o.tissue = loaded_tissue_model(parent);
      if (!o.features || o.features->items.empty()) o.features = loaded_feature_lines(parent);
      return {};
    }
    // A scan-built model, one made before the tissue model existed, or a chart without its
    // parent: the clamped patch, said in every result.
    o.domain = closure::Domain::Patch;
    return "the model has no whole-face tissue model (a surface-scan model, one made before it "
           "existed, or a local chart whose parent model is gone, has changed or has none): "
           "solved on the 1992 clamped patch, whose rim decides more of the answer; build it with "
           "`caps model tissue MODEL` (a CT-built model; for a chart, its parent)";
  }
  o.tissue = loaded_tissue_model(model_dir);
  return {};
}

namespace {

// The request's plan, read once (empty for a bare border), after checking that it gives one of
// the two.
std::optional<plan::Plan> plan_of(const MeshRequest& r) {
  if (r.plan.empty() == r.border.empty())
    throw InvalidInput("give the wound as --plan plan.json (from caps plan new) or as --border "
                       "border.json, one of the two");
  if (r.plan.empty()) return std::nullopt;
  return plan::read_plan(r.plan);
}

// A mesh read from files whose elements are inverted or degenerate before any load is a bad
// file (nodes in the wrong order, mirrored coordinates), not a failed solve: refused naming the
// file and the first such element, with the Jacobian determinant at its Gauss point.
void refuse_inverted_input(const fem::Mesh& mesh, const std::string& dir) {
  Eigen::VectorXd N;
  Eigen::MatrixX3d dN;
  for (int e = 0; e < static_cast<int>(mesh.n_elements()); ++e) {
    const fem::ElementType type = mesh.elements[e].type;
    const Eigen::MatrixX3d X = fem::element_coordinates(mesh, e);
    const auto& rule = fem::quadrature(type);
    for (std::size_t q = 0; q < rule.size(); ++q) {
      fem::shape_functions(type, rule[q].xi, N, dN);
      const double det = (dN.transpose() * X).determinant();
      if (!(det > 0))
        throw InvalidInput(cat(dir, "/mesh.vtu: element ", e, " (", fem::element_type_name(type),
                               ") is inverted or degenerate before any load (Jacobian "
                               "determinant ", det, " mm^3 at Gauss point ", q, "); the mesh "
                               "file is damaged: check its node order (mesh.hpp) and that no "
                               "nodes coincide, or mesh the wound again (caps mesh)"));
    }
  }
}

// The model a plan is meshed and solved on when the request names `model`: that one, or the
// local chart of it the plan lies on (detail::plan_model_dir); `note` then says so.
std::string model_for_plan(const std::string& model, const plan::Plan& plan, std::string* note) {
  const std::string dir = detail::plan_model_dir(model, plan.model, plan.model_hash);
  if (dir != model && note)
    *note = cat("the plan lies on ", dir, ", a local chart of ", model, " facing skin that ",
                model, "'s cylindrical image cannot hold (caps plan new made it): meshed on the "
                "chart, closed in the whole face");
  return dir;
}

double max_norm(const Eigen::MatrixX3d& u) { return u.rows() ? u.rowwise().norm().maxCoeff() : 0.0; }

}  // namespace

// ---- mesh ---------------------------------------------------------------------------------

MeshResult run_mesh(const MeshRequest& r, Reporter* reporter) {
  require_utf8(r.model, "the model folder");
  require_utf8(r.plan.empty() ? r.border : r.plan, "the wound's file");
  detail::refuse_output_over_inputs(r);
  const closure::SimulateOptions o = simulate_options(r.meshing, {});
  const std::optional<plan::Plan> plan = plan_of(r);
  const mesher::WoundBorder border =
      plan ? plan::wound_border(*plan) : plan::read_wound_border(r.border);
  std::string chart_note;
  const std::string model_dir = plan ? model_for_plan(r.model, *plan, &chart_note) : r.model;
  if (!chart_note.empty()) warn(reporter, chart_note);
  OutputDirectory out(r.output, r.force);
  const auto loaded = loaded_model(model_dir);
  const PatientModel& model = *loaded;
  check_mesh_budget(border, model, r.meshing);
  mesher::WoundMesh w = mesher::mesh_wound(border, model, o.surface, o.continuum, reporter);
  const std::string wound = r.plan.empty() ? r.border : r.plan;
  w.continuum.mesh.model = model_dir;
  w.continuum.mesh.plan = wound;
  fem::write_mesh_dir(w.continuum.mesh, out.path());
  fem::write_inp(w.continuum.mesh, out.path() / "mesh.inp");
  if (!r.no_pictures) {
    mesher::write_surface_mesh_png(out.path() / "surface.png", w.surface,
                                cat("caps mesh: surface mesh of ", wound));
    mesher::write_cross_section_png(out.path() / "section.png", w.surface, model, o.continuum,
                                 cat("caps mesh: cross-section of ", wound));
  }
  const auto& s = w.surface;
  const auto& c = w.continuum;
  MeshResult m;
  m.output = r.output;
  m.surface_vertices = s.n_vertices();
  m.quads = s.quality.n_quads;
  m.triangles = s.quality.n_triangles;
  m.surface_layers = s.n_layers;
  m.trimmed_polygons = s.trimmed_polygons;
  m.extent_mm = s.extent_mm;
  m.wound_size_mm = s.wound_size_mm;
  m.min_angle_deg = s.quality.min_angle_deg;
  m.max_angle_deg = s.quality.max_angle_deg;
  m.max_aspect_ratio = s.quality.max_aspect_ratio;
  m.mean_aspect_ratio = s.quality.mean_aspect_ratio;
  m.nodes = static_cast<int>(c.mesh.n_nodes());
  m.elements = static_cast<int>(c.mesh.n_elements());
  for (const auto& e : c.mesh.elements) m.hex20 += e.type == fem::ElementType::Hex20;
  for (const auto& e : c.mesh.elements) m.wedge15 += e.type == fem::ElementType::Wedge15;
  m.layers = c.n_layers;
  m.fixed_nodes = static_cast<int>(c.mesh.fixed_nodes.size());
  m.suture_pairs = static_cast<int>(c.mesh.sutures.size());
  m.rim = r.meshing.rim;
  m.tissue = mesher::tissue_layers_name(c.tissue);
  m.min_thickness_mm = c.min_thickness_mm;
  m.max_thickness_mm = c.max_thickness_mm;
  m.min_jacobian = c.min_jacobian;
  m.warnings = c.mesh.warnings;
  write_text_atomic(out.path() / "summary.json", to_json(m) + "\n");
  out.commit();
  return m;
}

std::string summary(const MeshResult& m) {
  return cat("caps mesh: ", m.elements, " elements (", m.hex20, " Hex20), ", m.nodes, " nodes, ",
             m.suture_pairs, " suture pairs; corner angles ", round_to(m.min_angle_deg, 1), "-",
             round_to(m.max_angle_deg, 1), " deg -> ", m.output);
}

// ---- simulate -----------------------------------------------------------------------------

AxisLengthening axis_lengthening(const Eigen::MatrixX3d& pre, const Eigen::MatrixX3d& post,
                                 const Eigen::Vector3d& axis) {
  if (pre.rows() < 2 || post.rows() != pre.rows())
    throw InvalidInput(cat("axis lengthening: ", pre.rows(), " loop nodes before and ",
                           post.rows(), " after closure; give the same nodes, at least two"));
  const Eigen::VectorXd s = pre * axis, t = post * axis;
  const double lo = s.minCoeff(), hi = s.maxCoeff(), tol = 1e-6 * std::max(hi - lo, 1.0);
  double near = std::numeric_limits<double>::infinity(), far = -near;
  for (Eigen::Index i = 0; i < s.size(); ++i) {
    if (s[i] <= lo + tol) near = std::min(near, t[i]);
    if (s[i] >= hi - tol) far = std::max(far, t[i]);
  }
  return {hi - lo, far - near};
}

CornerLengthening corner_lengthening(const Eigen::MatrixX3d& pre, const Eigen::MatrixX3d& post,
                                     const std::vector<std::array<int, 4>>& sutures) {
  if (post.rows() != pre.rows())
    throw InvalidInput(cat("corner lengthening: ", pre.rows(), " loop nodes before and ",
                           post.rows(), " after closure; give the same nodes"));
  std::vector<int> corners;
  for (const auto& q : sutures)
    for (const int c : {q[0] == q[2] ? q[0] : -1, q[1] == q[3] ? q[1] : -1})
      if (c >= 0 && c < pre.rows() && std::find(corners.begin(), corners.end(), c) == corners.end())
        corners.push_back(c);
  std::sort(corners.begin(), corners.end());
  CornerLengthening out;
  for (std::size_t i = 0; i < corners.size(); ++i)
    for (std::size_t j = i + 1; j < corners.size(); ++j) {
      const double d = (pre.row(corners[i]) - pre.row(corners[j])).norm();
      if (d > out.before_mm) out = {d, (post.row(corners[i]) - post.row(corners[j])).norm(), corners[i], corners[j]};
    }
  return out;
}

namespace {

// The loop nodes' skin positions before and after the closure (#L×3 each, LPS mm).
std::pair<Eigen::MatrixX3d, Eigen::MatrixX3d> loop_positions(const closure::Simulation& sim) {
  const std::vector<int>& loop = sim.wound.surface.loop_vertex;
  const fem::Mesh& mesh = sim.wound.continuum.mesh;
  Eigen::MatrixX3d pre(static_cast<Eigen::Index>(loop.size()), 3), post(pre.rows(), 3);
  for (std::size_t i = 0; i < loop.size(); ++i) {
    const int n = sim.wound.continuum.skin_node[static_cast<std::size_t>(loop[i])];
    pre.row(static_cast<Eigen::Index>(i)) = mesh.nodes.row(n);
    post.row(static_cast<Eigen::Index>(i)) = mesh.nodes.row(n) + sim.result.displacement_mm.row(n);
  }
  return {pre, post};
}

// The simulation's lengthening along its plan's axis (the frame's x, the orientation, as the
// tangent at the plan's centre).
AxisLengthening plan_lengthening(const closure::Simulation& sim, const plan::Plan& plan,
                                 const PatientModel& model) {
  const auto [pre, post] = loop_positions(sim);
  const auto on_skin = [&](double x_mm) {
    const Eigen::Vector2d tz = plan.frame.to_theta_z(Eigen::Vector2d(x_mm, 0));
    return model.skin_point(tz[0], tz[1]);
  };
  return axis_lengthening(pre, post, (on_skin(0.5) - on_skin(-0.5)).normalized());
}

}  // namespace

SimulateResult simulation_summary(const closure::Simulation& sim,
                                  const closure::SimulateOptions& o, const plan::Plan& plan,
                                  const PatientModel& model) {
  SimulateResult s;
  const auto& res = sim.result;
  s.elements = static_cast<int>(sim.wound.continuum.mesh.n_elements());
  s.nodes = static_cast<int>(sim.wound.continuum.mesh.n_nodes());
  s.suture_pairs = static_cast<int>(sim.wound.continuum.mesh.sutures.size());
  s.max_displacement_mm = max_norm(res.displacement_mm);
  s.closing_force_n = res.total_suture_force_n;
  s.max_suture_force_n = fem::max_suture_pair_force_n(res);
  s.max_suture_gap_mm = sim.max_suture_gap_mm;
  s.strain_energy_mj = res.strain_energy_mj;
  s.warnings = sim.wound.continuum.mesh.warnings;
  s.domain = closure::domain_name(o.domain);
  s.patch_nodes = static_cast<int>(sim.wound.continuum.mesh.n_nodes());
  s.patch_elements = static_cast<int>(sim.wound.continuum.mesh.n_elements());
  if (sim.face) {
    const closure::FaceDomain& f = *sim.face;
    s.nodes = static_cast<int>(f.mesh.n_nodes());
    s.elements = static_cast<int>(f.mesh.n_elements());
    s.face_radius_mm = f.radius_mm;
    s.face_tets = f.tets;
    s.tied_nodes = f.tied_nodes;
    s.untied_nodes = f.untied_nodes;
    s.max_tie_distance_mm = f.max_tie_distance_mm;
    s.attached_nodes = f.attached_nodes;
    s.held_nodes = f.held_nodes;
    s.face_notes = f.notes;
  }
  s.features_json = feature_displacements_to_json(sim.features);
  for (const FeatureDisplacement& f : sim.features) s.feature_sentences.push_back(f.sentence);
  s.material = sim.wound.continuum.mesh.materials.at(0)->name();  // the skin's (layer 0)
  s.prestretch = res.prestretch;
  s.gape_mm = sim.gape_mm;
  s.load_steps = static_cast<int>(res.newton_steps.size());
  s.newton_iterations = res.newton_iterations;
  s.inverted_elements = sim.inverted_elements;
  s.suture_spacing_mm = sim.sutures.spacing_mm;
  s.sutures = static_cast<int>(sim.sutures.sutures.size());
  s.max_force_per_suture_n = sim.sutures.max_suture_force_n;
  s.force_per_mm_n = sim.sutures.force_per_mm_n;
  s.wound_length_mm = sim.sutures.wound_length_mm;
  s.sutures_total_force_n = sim.sutures.total_force_n;
  s.compressive_sutures = static_cast<int>(sim.sutures.compressive.size());
  s.compressive_force_n = sim.sutures.compressive_force_n;
  const AxisLengthening lengthening = plan_lengthening(sim, plan, model);
  s.axis_length_before_mm = lengthening.before_mm;
  s.axis_length_after_mm = lengthening.after_mm;
  const auto [pre, post] = loop_positions(sim);
  const CornerLengthening corners = corner_lengthening(pre, post, sim.wound.surface.sutures);
  s.corner_length_before_mm = corners.before_mm;
  s.corner_length_after_mm = corners.after_mm;
  s.corner_a = corners.corner_a;
  s.corner_b = corners.corner_b;
  if (corners.corner_a < 0) {  // no two closed corners: the headline is the axis projection
    s.corner_length_before_mm = s.axis_length_before_mm;
    s.corner_length_after_mm = s.axis_length_after_mm;
  }
  s.solve_s = res.timings.total_s;
  return s;
}

SimulateResult write_closure(closure::Simulation& sim, const closure::SimulateOptions& o,
                             const plan::Plan& plan, const std::string& plan_path,
                             const PatientModel& model, const std::string& model_dir,
                             const fs::path& dir, bool mesh_pictures) {
  sim.wound.continuum.mesh.model = model_dir;
  sim.wound.continuum.mesh.plan = plan_path;
  if (sim.face) {  // the whole face's mesh is the one written: it names them too
    sim.face->mesh.model = model_dir;
    sim.face->mesh.plan = plan_path;
  }
  closure::write_simulation(sim, model, o, dir, fs::path(plan_path).filename().string(),
                            mesh_pictures);
  // The plan closed, beside its result: caps plan sheet --result refuses another plan's result.
  plan::write_plan(dir / "plan.json", plan);
  return simulation_summary(sim, o, plan, model);
}

SimulateResult run_simulate(const SimulateRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  closure::SimulateOptions o = simulate_options(r.meshing, r.solver);
  // Both names are recorded in result.json (JSON is UTF-8).
  require_utf8(r.model, "the model folder");
  require_utf8(r.plan, "the plan file");
  const plan::Plan plan = plan::read_plan(r.plan);
  std::string chart_note;
  const std::string model_dir = model_for_plan(r.model, plan, &chart_note);
  const std::string domain_warning = set_domain(o, r.domain, model_dir);
  if (!(r.suture_spacing > 0) || !std::isfinite(r.suture_spacing))
    throw InvalidParameter(cat("{suture_spacing} ", r.suture_spacing, ": give the distance "
                               "between sutures in mm, > 0 (e.g. 5)"));
  o.suture_spacing_mm = r.suture_spacing;
  if (r.tension_map && !r.render)
    throw InvalidInput("--tension-map draws on the rendered images; add --render");
  OutputDirectory out(r.output, r.force);
  const auto loaded = loaded_model(model_dir);
  const PatientModel& model = *loaded;
  check_mesh_budget(plan::wound_border(plan), model, r.meshing);
  if (!domain_warning.empty()) warn(reporter, domain_warning);
  closure::Simulation sim = closure::simulate(model, plan, o, reporter);
  if (!chart_note.empty()) sim.wound.continuum.mesh.warnings.push_back(chart_note);
  if (!domain_warning.empty()) sim.wound.continuum.mesh.warnings.push_back(domain_warning);
  if (const std::string doubt = placement_doubt(model_dir, model, plan.placement); !doubt.empty()) {
    warn(reporter, doubt);
    sim.wound.continuum.mesh.warnings.push_back(doubt);
  }
  SimulateResult s = write_closure(sim, o, plan, r.plan, model, model_dir, out.path(),
                                   !r.no_mesh_pictures);
  s.output = r.output;
  if (r.render) {
    const render::DrawnSkin drawn = render::load_drawn_skin(model, model_dir, reporter);
    render::SimulationPictures pictures;
    pictures.tension_map = r.tension_map;
    pictures.drawn = &drawn;
    pictures.plan = &plan;
    for (const fs::path& p : render::render_simulation(
             model, sim,
             {render::View::Front, render::View::Oblique, render::View::Side, render::View::Plan},
             {}, out.path(), pictures, reporter))
      s.images.push_back(p.filename().string());
  }
  // What --json prints, kept with the result: the feature lines' displacements and the forces
  // per suture are not in result.json (caps plan sheet --result reads them here).
  write_text_atomic(out.path() / "summary.json", to_json(s) + "\n");
  out.commit();
  return s;
}

std::string summary(const SimulateResult& s) {
  std::string features;
  for (const std::string& f : s.feature_sentences) features += cat("; ", f);
  return cat("caps simulate: ", s.elements, " elements",
             s.domain == "face" ? cat(" (the whole face within ", std::round(s.face_radius_mm),
                                      " mm)")
                                : std::string(" (the clamped patch)"),
             ", closing force ",
             round_to(s.closing_force_n, 2), " N (", s.sutures, " sutures every ",
             round_to(s.suture_spacing_mm, 1), " mm: up to ", round_to(s.max_force_per_suture_n, 2),
             " N each; ", round_to(s.force_per_mm_n, 3), " N per mm of wound",
             s.compressive_sutures > 0
                 ? cat("; ", s.compressive_sutures, " more pressed shut, ",
                       round_to(-s.compressive_force_n, 2), " N of compression")
                 : std::string(),
             "), max displacement ",
             round_to(s.max_displacement_mm, 2), " mm, suture gap after closure ",
             s.max_suture_gap_mm < 1e-6 ? std::string("0") : cat(round_sig(s.max_suture_gap_mm, 2)),
             " mm",
             s.prestretch != 1 ? cat("; skin prestretched ", s.prestretch, ": the open wound gapes ",
                                     round_to(s.gape_mm, 2), " mm")
                               : std::string(),
             features, " -> ", s.output);
}

// ---- solve --------------------------------------------------------------------------------

SolveResult run_solve(const SolveRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  const closure::SimulateOptions so = simulate_options({}, r.solver);
  fem::SolveOptions o = so.solve;
  if (r.E && !(*r.E > 0 && std::isfinite(*r.E)))
    throw InvalidInput(cat("--E ", *r.E, ": give Young's modulus in kPa, > 0"));
  OutputDirectory out(r.output, r.force);
  fem::Mesh mesh = fem::read_mesh_dir(r.mesh);
  refuse_inverted_input(mesh, r.mesh);
  if (r.E || r.nu)
    for (auto& [layer, m] : mesh.materials) {
      fem::MaterialParameters changes;
      if (r.E) changes["E"] = *r.E * 1e-3;
      if (r.nu) changes["nu"] = *r.nu;
      m = fem::with_parameters(*m, changes, "--E/--nu");
    }
  set_materials(mesh, r.solver);
  Progress progress(reporter, "solving", 1);
  o.reporter = reporter;
  const fem::SolveResult res = fem::solve(mesh, o);
  progress.done();
  fem::write_result_dir(mesh, res, out.path());
  out.commit();
  SolveResult s;
  s.output = r.output;
  s.solver = res.solver;
  s.equations = static_cast<int>(res.n_equations);
  s.max_displacement_mm = max_norm(res.displacement_mm);
  s.max_von_mises_mpa = res.von_mises_mpa.size() ? res.von_mises_mpa.maxCoeff() : 0.0;
  s.total_suture_force_n = res.total_suture_force_n;
  s.strain_energy_mj = res.strain_energy_mj;
  s.warnings = mesh.warnings;
  s.total_s = res.timings.total_s;
  return s;
}

std::string summary(const SolveResult& s) {
  return cat("caps solve: ", s.equations, " equations (", s.solver, ") in ", round_to(s.total_s, 2),
             " s; max displacement ", round_to(s.max_displacement_mm, 3), " mm, closing force ",
             round_to(s.total_suture_force_n, 2), " N -> ", s.output);
}

// ---- fem box ------------------------------------------------------------------------------

BoxResult run_box(const BoxRequest& r, Reporter*) {
  fem::BoxOptions o;
  const auto s = parse_numbers<3>(r.box_size, "--box-size", "mm along x,y,z");
  const auto c = parse_numbers<3>(r.cells, "--cells", "cells along x,y,z");
  for (int k = 0; k < 3; ++k) {
    if (c[k] != static_cast<int>(c[k]))
      throw InvalidInput(cat("--cells ", r.cells, ": cell counts must be whole numbers"));
    o.size_mm[k] = s[k];
    o.cells[k] = static_cast<int>(c[k]);
  }
  // --cells 1000,1000,1000 ran out of memory after trying; a box is a test mesh: up to 1e6 cells.
  const double n_cells = c[0] * c[1] * c[2];
  if (!(n_cells <= 1e6))
    throw InvalidInput(cat("--cells ", r.cells, ": ", n_cells, " cells, more than the limit of "
                           "1e6 for a test box; give fewer cells"));
  o.slot = r.slot;
  o.wedges = r.wedges;
  OutputDirectory out(r.output, r.force);
  const fem::Mesh m = fem::make_box_mesh(o);
  fem::write_mesh_dir(m, out.path());
  out.commit();
  return {r.output, static_cast<int>(m.n_nodes()), static_cast<int>(m.n_elements()),
          static_cast<int>(m.sutures.size())};
}

std::string summary(const BoxResult& b) {
  return cat("caps fem box: ", b.elements, " elements, ", b.nodes, " nodes, ", b.sutures,
             " suture pairs -> ", b.output);
}

// ---- compare ------------------------------------------------------------------------------

CompareResult run_compare(const CompareRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  if (r.meshing.constant_thickness != 0)
    throw InvalidInput("compare meshes the measured and a constant thickness itself; give the "
                       "constant one with --thickness, not --constant-thickness");
  closure::SimulateOptions o = simulate_options(r.meshing, r.solver);
  require_utf8(r.model, "the model folder");
  require_utf8(r.plan, "the plan file");
  const plan::Plan plan = plan::read_plan(r.plan);
  std::string chart_note;
  const std::string model_dir = model_for_plan(r.model, plan, &chart_note);
  if (!chart_note.empty()) warn(reporter, chart_note);
  if (const std::string w = set_domain(o, r.domain, model_dir); !w.empty()) warn(reporter, w);
  OutputDirectory out(r.output, r.force);
  const auto loaded = loaded_model(model_dir);
  const PatientModel& model = *loaded;
  check_mesh_budget(plan::wound_border(plan), model, r.meshing);
  const study::Comparison c = study::compare_thickness(model, plan, r.thickness, o, reporter);
  const std::string name = fs::path(r.plan).filename().string();
  const render::DrawnSkin drawn = render::load_drawn_skin(model, model_dir, reporter);
  render::SimulationPictures pictures;
  pictures.drawn = &drawn;
  pictures.plan = &plan;
  render::write_comparison_report(c, model, o, out.path(), name, {}, reporter, pictures);
  out.commit();
  CompareResult s;
  s.output = r.output;
  s.comparison_json = study::comparison_json(c, name);
  s.measured_closing_force_n = c.measured_summary.closing_force_n;
  s.constant_closing_force_n = c.constant_summary.closing_force_n;
  s.measured_max_displacement_mm = c.measured_summary.max_displacement_mm;
  s.constant_max_displacement_mm = c.constant_summary.max_displacement_mm;
  s.layers_closing_force_n = c.layered_summary.closing_force_n;
  s.layers_max_displacement_mm = c.layered_summary.max_displacement_mm;
  s.layers_tissue = c.layered_summary.tissue;
  s.constant_thickness_mm = c.constant_thickness_mm;
  s.warnings = c.warnings;
  s.domain = closure::domain_name(o.domain);
  return s;
}

std::string summary(const CompareResult& s) {
  // Named, as simulate's line names its domain: on the clamped patch (--domain patch) the forces
  // differ from the whole face's for the same plan (Cranium's demo ellipse: 3.71 against 3.00 N).
  return cat("caps compare (", s.domain == "face" ? "the whole face" : "the clamped 1992 patch",
             "): closing force ", round_to(s.measured_closing_force_n, 2),
             " N (measured) vs ", round_to(s.constant_closing_force_n, 2), " N (constant ",
             round_to(s.constant_thickness_mm, 1), " mm) vs ", round_to(s.layers_closing_force_n, 2),
             " N (", s.layers_tissue == "measured" ? "measured layers" : "no layers: one material",
             "); largest displacement ", round_to(s.measured_max_displacement_mm, 2), " vs ",
             round_to(s.constant_max_displacement_mm, 2), " vs ",
             round_to(s.layers_max_displacement_mm, 2), " mm -> ", s.output, "/report.html");
}

}  // namespace caps::app

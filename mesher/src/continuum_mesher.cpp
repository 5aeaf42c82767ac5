#include "caps/mesher/continuum_mesher.hpp"

#include "caps/core/error.hpp"
#include "caps/core/plane_geometry.hpp"
#include "caps/core/point_bins.hpp"
#include "caps/core/reporter.hpp"
#include "caps/fem/elements.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/core/union_find.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <map>
#include <optional>
#include <set>
#include <string>

namespace caps::mesher {

using namespace caps::fem;

namespace {
// How much farther apart than at the skin a deep suture pair's nodes may lie (mm; and half the
// skin's gap): beyond it the wall there is not sewn (try_mesh_continuum).
constexpr double kDeepGapSlackMm = 2.0;
}  // namespace

const char* rim_condition_name(RimCondition rim) {
  switch (rim) {
    case RimCondition::Fixed: return "fixed";
    case RimCondition::Free: return "free";
    case RimCondition::Tied: break;
  }
  return "tied";
}

const char* base_condition_name(BaseCondition base) {
  return base == BaseCondition::Slide ? "slide" : "free";
}

BaseCondition parse_base_condition(const std::string& name) {
  if (name == "slide") return BaseCondition::Slide;
  if (name == "free") return BaseCondition::Free;
  throw InvalidInput(cat("base condition '", name, "': expected slide or free"));
}

const char* tissue_layers_name(TissueLayers tissue) {
  switch (tissue) {
    case TissueLayers::Uniform: return "uniform";
    case TissueLayers::Measured: return "measured";
    case TissueLayers::Auto: break;
  }
  return "auto";
}

TissueLayers parse_tissue_layers(const std::string& name) {
  if (name == "auto") return TissueLayers::Auto;
  if (name == "uniform") return TissueLayers::Uniform;
  if (name == "measured") return TissueLayers::Measured;
  throw InvalidInput(cat("tissue layers '", name, "': expected auto, uniform or measured"));
}

RimCondition parse_rim_condition(const std::string& name) {
  if (name == "fixed") return RimCondition::Fixed;
  if (name == "free") return RimCondition::Free;
  if (name == "tied") return RimCondition::Tied;
  throw InvalidInput(cat("rim condition '", name, "': expected fixed, free or tied"));
}

Eigen::VectorXd min_element_jacobians(const Mesh& mesh) {
  Eigen::VectorXd out(static_cast<Eigen::Index>(mesh.n_elements()));
  Eigen::VectorXd N;
  Eigen::MatrixX3d dN;
  for (std::size_t e = 0; e < mesh.n_elements(); ++e) {
    const ElementType type = mesh.elements[e].type;
    const Eigen::MatrixX3d X = element_coordinates(mesh, static_cast<int>(e));
    double jmin = 1e300;
    for (const auto& q : quadrature(type)) {
      shape_functions(type, q.xi, N, dN);
      const Eigen::Matrix3d J = X.transpose() * dN;
      jmin = std::min(jmin, J.determinant());
    }
    out[static_cast<Eigen::Index>(e)] = jmin;
  }
  return out;
}

namespace {

// Auto resolved: measured where the model has layer maps and at least a quarter of the surface
// mesh's vertices lie on cells whose layers were measured (a stray measured cell in a model
// without fat does not switch a whole mesh). Measured without layer maps is refused.
TissueLayers resolve_tissue(const SurfaceMesh& surface, const PatientModel& model,
                            TissueLayers tissue) {
  if (tissue == TissueLayers::Uniform) return tissue;
  if (!model.has_layers()) {
    if (tissue == TissueLayers::Auto) return TissueLayers::Uniform;
    throw InvalidParameter("mesh: measured tissue layers need the model's layer maps "
                       "(thickness_skin/fat/deep.nrrd), which this model has not (an MR or scan "
                       "model, or one built with --no-layers); use {tissue} uniform");
  }
  if (tissue == TissueLayers::Measured) return tissue;
  int n_measured = 0;
  for (int v = 0; v < surface.n_vertices(); ++v) {
    const double theta = surface.theta_z(v, 0), z = surface.theta_z(v, 1);
    n_measured += model.has_z(z) && model.layer_flags_at(theta, z) == 0;
  }
  return 4 * n_measured >= surface.n_vertices() ? TissueLayers::Measured : TissueLayers::Uniform;
}

}  // namespace

LayerStack::LayerStack(const SurfaceMesh& surface, const PatientModel& model,
                       const ContinuumMeshOptions& o)
    : model_(&model), min_tissue_layer_mm_(o.min_tissue_layer_mm) {
  if (resolve_tissue(surface, model, o.tissue) == TissueLayers::Measured)
    per_ = std::max(1, static_cast<int>(std::lround(o.n_layers / 3.0)));
  const int NL = per_ > 0 ? 3 * per_ : o.n_layers;
  // Uniform: layer interfaces as fractions of the depth, layer k grading^k times the first.
  fractions_.assign(static_cast<std::size_t>(NL) + 1, 0.0);
  for (int k = 0; k < NL; ++k) fractions_[k + 1] = fractions_[k] + std::pow(o.grading, k);
  for (double& f : fractions_) f /= fractions_[NL];
}

void LayerStack::depths(double theta, double z, double T, std::vector<double>& D,
                        bool* no_fat) const {
  const int NL = n_layers();
  D.resize(static_cast<std::size_t>(NL) + 1);
  if (no_fat) *no_fat = false;
  if (!measured()) {
    for (int k = 0; k <= NL; ++k) D[k] = fractions_[k] * T;
    return;
  }
  const PatientModel& model = *model_;
  std::array<double, 3> t{std::max(0.0, model.thickness_skin(theta, z)),
                          std::max(0.0, model.thickness_fat(theta, z)),
                          std::max(0.0, model.thickness_deep(theta, z))};
  const double sum = t[0] + t[1] + t[2];
  // The layers in proportion to T (they sum to the model's thickness; a constant depth scales
  // them); without any depth the column is skin (cannot happen on a model with layers).
  if (sum > 0)
    for (double& x : t) x *= T / sum;
  else
    t = {T, 0, 0};
  const double thinnest = std::min(min_tissue_layer_mm_, T / 4);
  if (no_fat) *no_fat = t[kFatLayer] < thinnest;
  for (int l = 0; l < 3; ++l)
    if (t[l] < thinnest) {
      const int thickest = static_cast<int>(std::max_element(t.begin(), t.end()) - t.begin());
      t[thickest] -= thinnest - t[l];
      t[l] = thinnest;
    }
  const int per = per_;
  D[0] = 0;
  for (int l = 0; l < 3; ++l)
    for (int i = 1; i <= per; ++i) D[l * per + i] = D[l * per] + i * t[l] / per;
  D[NL] = T;  // exactly, whatever the round-off of the sums
}

namespace {

// Two neighbouring columns `apart` mm apart on the skin, `depth_a` and `depth_b` deep, stand on
// either side of a bony rim (kMaxDepthSlope).
bool across_bony_rim(double depth_a, double depth_b, double apart) {
  return std::abs(depth_a - depth_b) > kMaxDepthSlope * apart;
}

// Why a column of the continuum mesh cannot stand at (theta, z) (empty if it can); `T` gets the
// soft-tissue thickness there.
std::string site_refusal(const PatientModel& model, const ContinuumMeshOptions& o, double theta,
                         double z, double* T) {
  const auto& g = model.grid();
  const double margin_mm = kEndRowsKeptFree * g.dz_mm;
  if (!model.has_z(z))
    return cat("mesh: the site at theta ", std::round(theta * 10) / 10, " deg, z ",
               std::round(z * 10) / 10, " mm lies outside the model's z range; use a smaller "
               "{extent} or a wound further from the model's ends");
  if (z < g.z0_mm + margin_mm || z > g.z_mm(g.n_z - 1) - margin_mm)
    return cat("mesh: the site at theta ", std::round(theta * 10) / 10, " deg, z ",
               std::round(z * 10) / 10, " mm lies within ", kEndRowsKeptFree,
               " rows of the model's top or bottom, too close to draw the skin around it; use "
               "a smaller {extent} or a wound further from the model's ends");
  if (const auto f = model.flags_at(theta, z); !flags_valid(f))
    return cat("mesh: the site at theta ", std::round(theta * 10) / 10, " deg, z ",
               std::round(z * 10) / 10, " mm lies on cells of the model that are not valid (",
               describe_flags(f), "); move the wound or use a smaller {extent}");
  const double r_top = model.r_skin(theta, z);
  *T = o.constant_thickness_mm > 0 ? o.constant_thickness_mm : model.thickness(theta, z);
  if (!(*T >= o.min_thickness_mm) || !(*T < r_top))
    return cat("mesh: the soft-tissue thickness at theta ", theta, " deg, z ", z, " mm is ", *T,
               " mm (minimum ", o.min_thickness_mm, " mm, skin radius ", r_top,
               " mm); there is no valid tissue layer to mesh there");
  return {};
}

// A continuum mesh, or why there is none: the surface mesh reaches where the model has no valid
// tissue (OffModel, the message of an OffModelError) or an element is inverted (Inverted): a
// caller with room to mesh less can try a smaller extent.
struct ContinuumAttempt {
  std::optional<ContinuumMesh> mesh;
  MeshRefusal refusal;  // when !mesh
  /// With `allow_cliffs`: the mesh crosses a bony rim, the message naming the place and the
  /// drop (empty when it crosses none).
  std::string cliff;
};

void check_continuum_options(const SurfaceMesh& surface, const ContinuumMeshOptions& o) {
  if (o.n_layers < 1 || o.n_layers > 50 || !(o.grading > 0) || !std::isfinite(o.grading))
    throw InvalidInput(cat("continuum mesher: layers ", o.n_layers, " must be in 1..50 and grading ",
                           o.grading, " positive"));
  if (!(o.undermine_mm >= 0) || !std::isfinite(o.undermine_mm))
    throw InvalidInput(cat("continuum mesher: undermining ", o.undermine_mm,
                           " mm must be 0 (none) or a positive distance from the wound"));
  if (surface.polygons.empty())
    throw InvalidInput("continuum mesher: the surface mesh has no polygons");
  if (!(o.min_tissue_layer_mm > 0) || !std::isfinite(o.min_tissue_layer_mm))
    throw InvalidInput(cat("continuum mesher: the thinnest tissue layer ", o.min_tissue_layer_mm,
                           " mm must be positive"));
}

ContinuumAttempt refused(MeshRefusal::Kind kind, const Eigen::Vector2d& tz, std::string why) {
  return ContinuumAttempt{std::nullopt, MeshRefusal{kind, tz.x(), tz.y(), std::move(why)}, {}};
}

std::string rim_refusal(const std::string& drop) {
  return cat("mesh: ", drop, " (a bony rim, such as the orbit's); move the wound or use a "
             "smaller {extent}");
}

// One continuum mesh in the making: the surface mesh's edges, the node columns of its vertices
// and edges, the elements, suture pairs, fixed nodes and the sliding base, one step each
// (build()). The fields are the steps' shared state.
struct ContinuumBuild {
  ContinuumBuild(const SurfaceMesh& surface, const PatientModel& model,
                 const ContinuumMeshOptions& o, bool allow_cliffs);
  ContinuumAttempt build();

  void collect_edges();
  void allocate_nodes();
  // The nodes of one column; returns why the site cannot be meshed (empty if it can).
  template <class NodeOf>
  std::string column(const Eigen::Vector2d& tz, NodeOf&& node_of, int n_half_levels, int step,
                     bool* no_fat);
  std::optional<ContinuumAttempt> place_vertex_columns();
  std::optional<ContinuumAttempt> find_bony_rims();
  std::optional<ContinuumAttempt> place_edge_columns();
  void assign_materials();
  void add_elements();
  void add_sutures();
  void fix_nodes();
  void add_sliding_base();
  std::optional<ContinuumAttempt> check_jacobians();

  int vnode(int v, int half_level) const { return v * per_vertex + half_level; }
  int enode(int e, int level) const { return NV * per_vertex + e * per_edge + level; }

  const SurfaceMesh& surface;
  const PatientModel& model;
  const ContinuumMeshOptions& o;
  const bool allow_cliffs;
  const LayerStack stack;
  const bool measured;
  // Measured: `per` element layers in each tissue layer (dermis, fat, deep).
  const int per;
  const int NL;  // element layers
  ContinuumAttempt attempt;
  ContinuumMesh& out;
  Mesh& mesh;
  Eigen::Vector2d cliff_at = Eigen::Vector2d::Zero();  // where attempt.cliff lies
  // Surface edges.
  std::map<std::pair<int, int>, int> edge_id;
  std::vector<std::pair<int, int>> edges;
  int NV = 0, NE = 0, per_vertex = 0, per_edge = 0;
  std::vector<char> fatless;  // measured: a vertex without fat
  std::vector<double> D;
  // Measured: each vertex column's interface depths. A mid-edge column takes the mean of its two
  // vertices' depths (scaled to its own thickness) instead of the maps' own value at the
  // midpoint: where the fat's depth jumps between neighbouring columns (noise in the maps, the
  // edge of a muscle) a mid-edge node sampled there lies far off the line between the corners'
  // nodes, and the quadratic element turns inside out (seen at the Cranium temple). Where the
  // depths vary linearly both are the same.
  std::vector<std::vector<double>> vertex_depths;
  std::vector<double> vertex_depth;  // each vertex column's depth
  const std::vector<double>* fractions = nullptr;  // set for a mid-edge column: depth / T
  std::set<std::pair<int, int>> pairs;  // suture pairs
  std::set<int> sutured, fixed, free_base;
};

ContinuumBuild::ContinuumBuild(const SurfaceMesh& surface, const PatientModel& model,
                               const ContinuumMeshOptions& o, bool allow_cliffs)
    : surface(surface), model(model), o(o), allow_cliffs(allow_cliffs), stack(surface, model, o),
      measured(stack.measured()), per(stack.per_tissue_layer()), NL(stack.n_layers()),
      out(attempt.mesh.emplace()), mesh(out.mesh) {
  out.n_layers = NL;
  out.tissue = measured ? TissueLayers::Measured : TissueLayers::Uniform;
  if (measured) {
    out.fat_top_level = per;
    out.fat_bottom_level = 2 * per;
  }
  collect_edges();
  allocate_nodes();
}

// `allow_cliffs`: a bony rim under the mesh is meshed across (its message kept in `cliff`)
// instead of counting as off the model, unless an element across it is inverted.
ContinuumAttempt ContinuumBuild::build() {
  if (auto refusal = place_vertex_columns()) return std::move(*refusal);
  if (auto refusal = find_bony_rims()) return std::move(*refusal);
  if (auto refusal = place_edge_columns()) return std::move(*refusal);
  assign_materials();
  add_elements();
  add_sutures();
  fix_nodes();
  if (o.base == BaseCondition::Slide) add_sliding_base();
  if (auto refusal = check_jacobians()) return std::move(*refusal);
  validate(mesh, "continuum mesh");
  return std::move(attempt);
}

void ContinuumBuild::collect_edges() {
  auto edge_of = [&](int a, int b) {
    const auto key = std::minmax(a, b);
    auto [it, inserted] = edge_id.try_emplace({key.first, key.second}, static_cast<int>(edges.size()));
    if (inserted) edges.emplace_back(key.first, key.second);
    return it->second;
  };
  for (const auto& poly : surface.polygons)
    for (std::size_t i = 0; i < poly.size(); ++i) edge_of(poly[i], poly[(i + 1) % poly.size()]);
}

void ContinuumBuild::allocate_nodes() {
  NV = surface.n_vertices();
  NE = static_cast<int>(edges.size());
  fatless.assign(static_cast<std::size_t>(NV), 0);
  per_vertex = 2 * NL + 1;
  per_edge = NL + 1;
  const int n_nodes = NV * per_vertex + NE * per_edge;
  mesh.nodes.resize(n_nodes, 3);
  out.node_theta_z.resize(n_nodes, 2);
  out.skin_node.resize(NV);
  for (int v = 0; v < NV; ++v) out.skin_node[v] = vnode(v, 0);
  out.node_level.resize(n_nodes);
  out.min_thickness_mm = 1e300;
  out.max_thickness_mm = 0;
  D.resize(static_cast<std::size_t>(NL) + 1);
  vertex_depths.resize(measured ? static_cast<std::size_t>(NV) : 0);
  vertex_depth.resize(static_cast<std::size_t>(NV));
}

template <class NodeOf>
std::string ContinuumBuild::column(const Eigen::Vector2d& tz, NodeOf&& node_of, int n_half_levels,
                                   int step, bool* no_fat) {
  const double theta = tz.x(), z = tz.y();
  double T = 0;
  if (std::string why = site_refusal(model, o, theta, z, &T); !why.empty()) return why;
  const double r_top = model.r_skin(theta, z);
  out.min_thickness_mm = std::min(out.min_thickness_mm, T);
  out.max_thickness_mm = std::max(out.max_thickness_mm, T);
  bool thin_fat = false;
  if (fractions != nullptr)
    for (int k = 0; k <= NL; ++k) D[k] = (*fractions)[k] * T;
  else
    stack.depths(theta, z, T, D, &thin_fat);
  if (thin_fat) ++out.widened_fat_columns;
  if (no_fat) *no_fat = thin_fat;
  for (int h = 0; h <= n_half_levels; h += step) {
    const int id = node_of(h);
    const double depth = h % 2 == 0 ? D[h / 2] : 0.5 * (D[h / 2] + D[h / 2 + 1]);
    // Nodes lie on the line from the skin point to the axis (paper section 6).
    mesh.nodes.row(id) = model.to_lps(theta, z, r_top - depth).transpose();
    out.node_theta_z.row(id) = tz.transpose();
    out.node_level[id] = 0.5 * h;
  }
  return {};
}

std::optional<ContinuumAttempt> ContinuumBuild::place_vertex_columns() {
  for (int v = 0; v < NV; ++v) {
    bool no_fat = false;
    if (std::string why = column(surface.theta_z.row(v).transpose(),
                                 [&](int h) { return vnode(v, h); }, 2 * NL, 1, &no_fat);
        !why.empty())
      return refused(MeshRefusal::Kind::OffModel, surface.theta_z.row(v).transpose(), std::move(why));
    fatless[v] = no_fat;
    if (measured) vertex_depths[v] = D;
    vertex_depth[v] = D[NL];
  }
  return std::nullopt;
}

std::optional<ContinuumAttempt> ContinuumBuild::find_bony_rims() {
  // A cliff in the bone under the mesh: the depth of two neighbouring columns differs by more
  // than kMaxDepthSlope times the distance between them on the skin. Rays that pass just below
  // a bony rim (the supraorbital rim into the orbit, the edge of a sinus) meet bone 20-30 mm
  // deeper than their neighbours; an element spanning that step is sheared so far that a thin
  // layer turns inside out, and the tissue it models is not the soft tissue over one bone. The
  // cliff counts as off the model, so the automatic extent stops short of it.
  for (const auto& [a, b] : edges) {
    const double apart = (mesh.nodes.row(vnode(a, 0)) - mesh.nodes.row(vnode(b, 0))).norm();
    if (across_bony_rim(vertex_depth[a], vertex_depth[b], apart)) {
      const Eigen::Vector2d tz = 0.5 * (surface.theta_z.row(a) + surface.theta_z.row(b)).transpose();
      std::string drop = cat("the bone under the skin at theta ", std::round(tz.x() * 10) / 10,
                             " deg, z ", std::round(tz.y() * 10) / 10, " mm drops from ",
                             std::round(std::min(vertex_depth[a], vertex_depth[b]) * 10) / 10, " to ",
                             std::round(std::max(vertex_depth[a], vertex_depth[b]) * 10) / 10,
                             " mm deep within ", std::round(apart * 10) / 10, " mm");
      if (!allow_cliffs) return refused(MeshRefusal::Kind::OffModel, tz, rim_refusal(drop));
      if (attempt.cliff.empty()) {
        attempt.cliff = std::move(drop);
        cliff_at = tz;
      }
    }
  }
  return std::nullopt;
}

std::optional<ContinuumAttempt> ContinuumBuild::place_edge_columns() {
  std::vector<double> edge_fractions(static_cast<std::size_t>(NL) + 1);
  for (int e = 0; e < NE; ++e) {
    // The mid-edge node of the top face: the midpoint in (theta, z), snapped to the skin.
    const Eigen::Vector2d tz =
        0.5 * (surface.theta_z.row(edges[e].first) + surface.theta_z.row(edges[e].second)).transpose();
    if (measured) {
      const auto& a = vertex_depths[edges[e].first];
      const auto& b = vertex_depths[edges[e].second];
      for (int k = 0; k <= NL; ++k) edge_fractions[k] = (a[k] + b[k]) / (a[NL] + b[NL]);
      fractions = &edge_fractions;
    }
    std::string why = column(tz, [&](int h) { return enode(e, h / 2); }, 2 * NL, 2, nullptr);
    fractions = nullptr;
    if (!why.empty()) return refused(MeshRefusal::Kind::OffModel, tz, std::move(why));
  }
  return std::nullopt;
}

// The layers' materials (Mesh::materials): the uniform or measured tissue's, and the surface layer's
// own (ContinuumMeshOptions::surface_material, the goh skin) where it is given.
void ContinuumBuild::assign_materials() {
  if (measured) {
    // Element layer ids are the tissue layers, each with its material.
    mesh.materials = {{kDermisLayer, o.dermis}, {kFatLayer, o.fat}, {kDeepLayer, o.deep}};
  } else {
    for (int k = 0; k < NL; ++k) mesh.materials.emplace(k, o.material);
  }
  if (o.surface_material) mesh.materials[0] = o.surface_material;
}

// Elements: polygons run counter-clockwise in (theta, z), i.e. seen from outside the skin;
// reversed, their right-hand normal points into the tissue as the element numbering needs.
void ContinuumBuild::add_elements() {
  mesh.flaps.assign(surface.flaps_theta_z.size(), {});
  for (std::size_t p = 0; p < surface.polygons.size(); ++p) {
    std::vector<int> v(surface.polygons[p].rbegin(), surface.polygons[p].rend());
    const int n = static_cast<int>(v.size());
    // The flap a polygon lies in: its centroid inside the flap's outline.
    Eigen::Vector2d centroid = Eigen::Vector2d::Zero();
    for (int i : v) centroid += surface.theta_z.row(i).transpose() / n;
    int flap = -1;
    for (std::size_t f = 0; f < surface.flaps_theta_z.size() && flap < 0; ++f)
      if (point_in_or_on_polygon(surface.flaps_theta_z[f], centroid)) flap = static_cast<int>(f);
    // Measured: a fat element whose corner columns mostly had no fat is deep tissue.
    int n_fatless = 0;
    for (int i : v) n_fatless += fatless[i];
    const bool fat_absent = 2 * n_fatless > n;
    for (int k = 0; k < NL; ++k) {
      Element el;
      el.layer = k;
      if (measured) {
        el.layer = k / per;
        if (el.layer == kFatLayer && fat_absent) el.layer = kDeepLayer;
      }
      el.type = n == 4 ? ElementType::Hex20 : ElementType::Wedge15;
      const int top_mid_off = n == 4 ? 8 : 6, bot_mid_off = n == 4 ? 12 : 9;
      const int centre = n == 4 ? 16 : 12;
      for (int i = 0; i < n; ++i) {
        const int e = edge_id.at(std::minmax(v[i], v[(i + 1) % n]));
        el.nodes[i] = vnode(v[i], 2 * k);
        el.nodes[n + i] = vnode(v[i], 2 * k + 2);
        el.nodes[top_mid_off + i] = enode(e, k);
        el.nodes[bot_mid_off + i] = enode(e, k + 1);
        el.nodes[centre + i] = vnode(v[i], 2 * k + 1);
      }
      if (flap >= 0) mesh.flaps[static_cast<std::size_t>(flap)].push_back(static_cast<int>(mesh.elements.size()));
      mesh.elements.push_back(el);
      out.element_polygon.push_back(static_cast<int>(p));
    }
  }
}

// Suture pairs along every sutured border edge, through all layers.
void ContinuumBuild::add_sutures() {
  auto add_pair = [&](int a, int b) {
    if (a != b && !pairs.count({b, a})) pairs.insert({a, b});
  };
  // The wall below the skin is sewn level to level while its twins lie about as far apart as the
  // skin's: over a depth step across the wound (a bony rim under it) the deep levels of the two
  // columns lie far apart (up to 24 mm for a 4 mm wide ellipse on Cranium's cheek), and tying
  // them would drag the deep tissue that far. There the wall is left open below (dead space under
  // the closure, as over a step the surgeon closes the layers that meet).
  // Returns whether the pair was sewn; the levels below one that is not are not sewn either.
  auto add_deep_pair = [&](int a, int b, int skin_a, int skin_b) {
    const double skin_gap = (mesh.nodes.row(skin_a) - mesh.nodes.row(skin_b)).norm();
    const double gap = (mesh.nodes.row(a) - mesh.nodes.row(b)).norm();
    if (gap > skin_gap + std::max(kDeepGapSlackMm, 0.5 * skin_gap)) return false;
    add_pair(a, b);
    return true;
  };
  const int nloop = static_cast<int>(surface.loop_vertex.size());
  // The vertices along the loop from a forward to b (the edges' chains joined).
  auto chain = [&](int a, int b) {
    std::vector<int> c;
    for (int e : plan::forward_edges(a, b, nloop)) {
      const auto& ec = surface.edge_chain[e];
      c.insert(c.end(), ec.begin() + (c.empty() ? 0 : 1), ec.end());
    }
    return c;
  };
  for (const auto& s : surface.sutures) {
    // The first side from a forward to b meets the second from c backward to d.
    const auto c1 = chain(s[0], s[1]);
    auto c2 = chain(s[3], s[2]);
    std::reverse(c2.begin(), c2.end());
    if (c1.size() != c2.size())
      throw InvalidInput(cat("mesh: suture (", s[0], ",", s[1], ")-(", s[2], ",", s[3],
                             ") joins edges with different node counts"));
    for (std::size_t i = 0; i < c1.size(); ++i) {
      if (c1[i] == c2[i]) continue;  // a closed corner
      for (int h = 0; h <= 2 * NL; ++h)
        if (!add_deep_pair(vnode(c1[i], h), vnode(c2[i], h), vnode(c1[i], 0), vnode(c2[i], 0))) break;
    }
    for (std::size_t i = 0; i + 1 < c1.size(); ++i) {
      const int e1 = edge_id.at(std::minmax(c1[i], c1[i + 1]));
      const int e2 = edge_id.at(std::minmax(c2[i], c2[i + 1]));
      if (e1 == e2) continue;
      for (int k = 0; k <= NL; ++k)
        if (!add_deep_pair(enode(e1, k), enode(e2, k), enode(e1, 0), enode(e2, 0))) break;
    }
  }
  for (const auto& [a, b] : pairs) {
    mesh.sutures.push_back({a, b});
    sutured.insert(a);
    sutured.insert(b);
  }
}

// Fixed nodes: the bottom (bone) except where undermined, and with a fixed rim the whole
// outer rim, unless sutured. Undermined: the site is within undermine_mm of the wound's border
// (the loop's chains) in the surface mesh's plane, or inside a flap the plan raises (its whole
// area is dissected off the deep tissue, on its outline included).
void ContinuumBuild::fix_nodes() {
  auto near_border = [&](const Eigen::Vector2d& p) {
    if (!(o.undermine_mm > 0)) return false;
    for (const auto& chain : surface.edge_chain)
      for (std::size_t i = 0; i + 1 < chain.size(); ++i) {
        const Eigen::Vector2d a = surface.xy_mm.row(chain[i]), b = surface.xy_mm.row(chain[i + 1]);
        const double L2 = (b - a).squaredNorm();
        const double t = L2 > 0 ? std::clamp((p - a).dot(b - a) / L2, 0.0, 1.0) : 0.0;
        if ((a + t * (b - a) - p).norm() < o.undermine_mm) return true;
      }
    return false;
  };
  auto in_flap = [&](const Eigen::Vector2d& tz) {
    for (const auto& poly : surface.flaps_theta_z)
      if (point_in_or_on_polygon(poly, tz)) return true;
    return false;
  };
  auto undermined = [&](int v0, int v1) {
    const Eigen::Vector2d xy = 0.5 * (surface.xy_mm.row(v0) + surface.xy_mm.row(v1)).transpose();
    const Eigen::Vector2d tz = 0.5 * (surface.theta_z.row(v0) + surface.theta_z.row(v1)).transpose();
    return near_border(xy) || in_flap(tz);
  };
  // Over an air cavity (kBaseCavity: nasal cavity, mouth) the base has no support at all: it is
  // neither fixed nor sliding (docs/fem.md); the tissue around it holds the column. So where the
  // tissue goes on below the model's base (kBaseTissue: the buccal fat, a skull defect's cover):
  // what lies deeper is not in the model, and a free base is the soft bound of its support.
  auto free_base_at = [&](int v0, int v1) {
    const Eigen::Vector2d tz = 0.5 * (surface.theta_z.row(v0) + surface.theta_z.row(v1)).transpose();
    return (model.flags_at(tz.x(), tz.y()) & (kBaseCavity | kBaseTissue)) != 0;
  };
  for (int v = 0; v < NV; ++v) {
    if (free_base_at(v, v)) free_base.insert(vnode(v, 2 * NL));
    else if (!undermined(v, v)) fixed.insert(vnode(v, 2 * NL));
  }
  for (int e = 0; e < NE; ++e) {
    if (free_base_at(edges[e].first, edges[e].second)) free_base.insert(enode(e, NL));
    else if (!undermined(edges[e].first, edges[e].second)) fixed.insert(enode(e, NL));
  }
  std::set<int> rim_nodes;
  const auto& rim = surface.outer_border;
  for (std::size_t i = 0; i < rim.size(); ++i) {
    const int e = edge_id.at(std::minmax(rim[i], rim[(i + 1) % rim.size()]));
    for (int h = 0; h <= 2 * NL; ++h) rim_nodes.insert(vnode(rim[i], h));
    for (int k = 0; k <= NL; ++k) rim_nodes.insert(enode(e, k));
  }
  out.rim_nodes.assign(rim_nodes.begin(), rim_nodes.end());
  if (o.rim == RimCondition::Fixed) fixed.insert(rim_nodes.begin(), rim_nodes.end());
  for (int id : fixed)
    if (!sutured.count(id)) mesh.fixed_nodes.push_back(id);
}

// The freed base slides on the deep tissue: held along the base's normal (the normal of the
// mesh's bottom surface, which lies on the bone or the cavity's base) by a spring
// kSlidingStiffness x E x column height, stiff enough that the support gives way by about
// 1e-6 mm under the closing forces, and free along the base. The nodes a suture ties together
// become one point at the wound's floor: they slide as one, with one spring along their mean
// normal (a spring on each would ask the closed point to lie on several planes at once, and
// leaving them free makes the floor kink against its sliding neighbours, a kink that stiffens
// without bound as the mesh is refined: docs/fem.md, "The freed base slides").
void ContinuumBuild::add_sliding_base() {
  const double E_sliding =
      measured ? std::max({o.dermis->stiffness_scale_mpa(), o.fat->stiffness_scale_mpa(),
                           o.deep->stiffness_scale_mpa()})
               : o.material->stiffness_scale_mpa();
  // The base's normal at a bottom node: the bottom faces' Newell vectors (area-weighted
  // normals) summed over the faces whose centres lie within kNormalRadiusMm of it (at least
  // the nearest face), turned to point up its column. A fixed radius rather than the node's
  // own faces: the bone under a CT's skin is bumpy at the scale of its voxels, and normals
  // from ever smaller faces would follow the bumps ever more closely (at 0.75 mm they strayed
  // a median 3 and up to 14 deg from their 3 mm mean on Cranium's forehead).
  constexpr double kNormalRadiusMm = 3.0;
  std::vector<Eigen::Vector3d> face_vector, face_centre;
  for (const auto& poly : surface.polygons) {
    Eigen::Vector3d n = Eigen::Vector3d::Zero(), c = Eigen::Vector3d::Zero();
    for (std::size_t i = 0; i < poly.size(); ++i) {
      const Eigen::Vector3d a = mesh.nodes.row(vnode(poly[i], 2 * NL)).transpose();
      const Eigen::Vector3d b = mesh.nodes.row(vnode(poly[(i + 1) % poly.size()], 2 * NL)).transpose();
      n += a.cross(b);
      c += a;
    }
    face_vector.push_back(n);
    face_centre.push_back(c / static_cast<double>(poly.size()));
  }
  Eigen::MatrixX3d centres(static_cast<Eigen::Index>(face_centre.size()), 3);
  for (std::size_t f = 0; f < face_centre.size(); ++f)
    centres.row(static_cast<Eigen::Index>(f)) = face_centre[f].transpose();
  const PointBins faces(std::move(centres), kNormalRadiusMm);
  auto base_normal = [&](const Eigen::Vector3d& x) {
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
    faces.near(x, [&](Eigen::Index f, double d2) {
      if (std::sqrt(d2) <= kNormalRadiusMm) n += face_vector[static_cast<std::size_t>(f)];
    });
    if (n.norm() > 0) return n;
    std::size_t nearest = 0;
    for (std::size_t f = 1; f < face_centre.size(); ++f)
      if ((face_centre[f] - x).norm() < (face_centre[nearest] - x).norm()) nearest = f;
    return face_vector[nearest];
  };
  std::map<int, std::pair<Eigen::Vector3d, Eigen::Vector3d>> base;  // bottom -> (normal, column)
  auto add_base = [&](int bottom, int top) {
    const Eigen::Vector3d up = (mesh.nodes.row(top) - mesh.nodes.row(bottom)).transpose();
    Eigen::Vector3d n = base_normal(mesh.nodes.row(bottom).transpose());
    if (n.dot(up) < 0) n = -n;
    if (!(n.norm() > 0)) n = up;
    base[bottom] = {n.normalized(), up};
  };
  for (int v = 0; v < NV; ++v) add_base(vnode(v, 2 * NL), vnode(v, 0));
  for (int e = 0; e < NE; ++e) add_base(enode(e, NL), enode(e, 0));
  // Suture groups among the bottom nodes, each named by its smallest node.
  UnionFind group(static_cast<int>(mesh.n_nodes()));
  for (const auto& [a, b] : pairs)
    if (base.count(a) && base.count(b)) group.unite(a, b);
  struct Merged {
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    double height = 0;
    int count = 0;
    bool unsupported = false;  // a member has a free base (a cavity or deeper tissue under it)
  };
  std::map<int, Merged> merged;  // group root -> its members' normals and column heights
  for (const auto& [bottom, nu] : base) {
    if (fixed.count(bottom)) continue;
    Merged& m = merged[group.find(bottom)];
    m.normal += nu.first;
    m.height += nu.second.norm();
    m.count += 1;
    m.unsupported |= free_base.count(bottom) > 0;
  }
  for (const auto& [r, m] : merged) {
    const double height = m.height / m.count;
    if (!m.unsupported && m.normal.norm() > 0 && height > 0)
      mesh.sliding.push_back({r, m.normal.normalized(), kSlidingStiffness * E_sliding * height});
  }
}

// Every element must have a positive Jacobian at every Gauss point.
std::optional<ContinuumAttempt> ContinuumBuild::check_jacobians() {
  const Eigen::VectorXd jac = min_element_jacobians(mesh);
  out.min_jacobian = jac.size() ? jac.minCoeff() : 0;
  for (Eigen::Index e = 0; e < jac.size(); ++e)
    if (!(jac[e] > 0)) {
      // Across a bony rim the rim is the cause: off the model, as without `allow_cliffs`.
      if (!attempt.cliff.empty())
        return refused(MeshRefusal::Kind::OffModel, cliff_at, rim_refusal(attempt.cliff));
      const auto& poly = surface.polygons[out.element_polygon[e]];
      Eigen::Vector2d c = Eigen::Vector2d::Zero();
      for (int id : poly) c += surface.theta_z.row(id).transpose();
      c /= static_cast<double>(poly.size());
      return refused(MeshRefusal::Kind::Inverted, c,
                     cat("mesh: element ", e, " (layer ", mesh.elements[e].layer,
                         ") near theta ", std::round(c.x() * 10) / 10, " deg, z ",
                         std::round(c.y() * 10) / 10, " mm is inverted or degenerate "
                         "(smallest Jacobian ", jac[e], "); use a smaller {mesh_size} or "
                         "fewer {layers} there"));
    }
  return std::nullopt;
}

ContinuumAttempt attempt_continuum(const SurfaceMesh& surface, const PatientModel& model,
                                   const ContinuumMeshOptions& o, bool allow_cliffs = false) {
  check_continuum_options(surface, o);
  ContinuumAttempt attempt = ContinuumBuild(surface, model, o, allow_cliffs).build();
  if (attempt.mesh) attempt.mesh->mesh.wedge_rule = o.wedge_rule;
  return attempt;
}

}  // namespace

void throw_refusal(const MeshRefusal& refusal) {
  if (refusal.kind == MeshRefusal::Kind::OffModel)
    throw OffModelError(refusal.message, refusal.theta_deg, refusal.z_mm);
  throw InvalidParameter(refusal.message);
}

MeshOutcome<ContinuumMesh> try_mesh_continuum(const SurfaceMesh& surface, const PatientModel& model,
                                              const ContinuumMeshOptions& o) {
  ContinuumAttempt attempt = attempt_continuum(surface, model, o);
  return {std::move(attempt.mesh), std::move(attempt.refusal)};
}

ContinuumMesh mesh_continuum(const SurfaceMesh& surface, const PatientModel& model,
                             const ContinuumMeshOptions& o) {
  MeshOutcome<ContinuumMesh> outcome = try_mesh_continuum(surface, model, o);
  if (!outcome) throw_refusal(outcome.refusal);
  return std::move(*outcome.mesh);
}

namespace {

// The surface mesh trimmed to the model: its layer polygons that reach a site where no column
// can stand (site_refusal(): the eye, the CT's end rows, cells the cylindrical image cannot hold)
// or that span a bony rim (a depth step steeper than kMaxDepthSlope) are left out, and so is
// whatever they cut off from the wound. The rest keeps its vertices, polygons and wound border;
// the trimmed border becomes part of the rim. Returns nothing when the wound itself or its stage-1
// fill reaches such a site, or when the polygons left do not form one ring around the wound (one
// rim loop, apart from the wound's, that touches no wound border vertex). `why` gets the first
// refusal met.
struct Trimmed {
  SurfaceMesh surface;
  int dropped = 0;  // polygons left out
  int pulled = 0;   // first-layer vertices pulled back onto the model
  std::string why;
};
// The state of trimmed_to_model(), one step each: the vertices and edges off the model, the
// polygons kept, the trimmed surface written.
struct Trimming {
  Trimming(SurfaceMesh surface, const PatientModel& model, const ContinuumMeshOptions& o,
           bool trim_rims);
  void mark_off_model_vertices();
  void mark_off_model_edges();
  bool keep_polygons();  // false: the wound itself or its stage-1 fill is off the model
  bool write_surface();  // false: not one ring around the wound, or nothing trimmed

  SurfaceMesh s;
  const PatientModel& model;
  const ContinuumMeshOptions& o;
  const bool trim_rims;
  const int NV, NP;
  Trimmed t;
  std::vector<double> T;
  std::vector<char> wound_vertex;
  std::set<std::pair<int, int>> wound_edges;
  std::vector<char> bad_vertex;
  std::map<std::pair<int, int>, char> bad_edge;
  std::vector<char> ok;  // polygons on valid sites
  std::map<std::pair<int, int>, std::vector<int>> edge_polygons;
  std::vector<char> kept;  // polygons kept
};

Trimming::Trimming(SurfaceMesh surface, const PatientModel& model, const ContinuumMeshOptions& o,
                   bool trim_rims)
    : s(std::move(surface)), model(model), o(o), trim_rims(trim_rims), NV(s.n_vertices()),
      NP(static_cast<int>(s.polygons.size())) {
  T.assign(static_cast<std::size_t>(NV), 0);
  wound_vertex.assign(static_cast<std::size_t>(NV), 0);
  for (const auto& chain : s.edge_chain)
    for (std::size_t i = 0; i < chain.size(); ++i) {
      wound_vertex[chain[i]] = 1;
      if (i + 1 < chain.size()) wound_edges.insert(std::minmax(chain[i], chain[i + 1]));
    }
  bad_vertex.assign(static_cast<std::size_t>(NV), 0);
}

void Trimming::mark_off_model_vertices() {
  for (int v = 0; v < NV; ++v) {
    std::string why = site_refusal(model, o, s.theta_z(v, 0), s.theta_z(v, 1), &T[v]);
    if (why.empty()) continue;
    bad_vertex[v] = 1;
    if (t.why.empty()) t.why = std::move(why);
  }
  // The first layer's outer vertices off the model are pulled towards the wound until they stand
  // on it, if that leaves the layer at least kKeptLayerFraction of its thickness there: without
  // them the wound's border would have no skin around it (a wound's tip 2 mm from the CT's end).
  constexpr double kKeptLayerFraction = 0.4;
  for (int p = 0; p < NP; ++p) {
    const auto& poly = s.polygons[p];
    Eigen::Vector2d w_tz = Eigen::Vector2d::Zero(), w_xy = Eigen::Vector2d::Zero();
    int n_w = 0;
    for (int v : poly)
      if (wound_vertex[v]) {
        w_tz += s.theta_z.row(v).transpose();
        w_xy += s.xy_mm.row(v).transpose();
        ++n_w;
      }
    if (n_w == 0) continue;
    w_tz /= n_w;
    w_xy /= n_w;
    for (int v : poly) {
      if (!bad_vertex[v] || wound_vertex[v]) continue;
      const Eigen::Vector2d tz = s.theta_z.row(v).transpose(), xy = s.xy_mm.row(v).transpose();
      for (double f = 0.05; f <= 1 - kKeptLayerFraction + 1e-9; f += 0.05) {
        const Eigen::Vector2d at = tz + f * (w_tz - tz);
        if (!site_refusal(model, o, at.x(), at.y(), &T[v]).empty()) continue;
        s.theta_z.row(v) = at.transpose();
        s.xy_mm.row(v) = (xy + f * (w_xy - xy)).transpose();
        bad_vertex[v] = 0;
        ++t.pulled;
        break;
      }
    }
  }
}

void Trimming::mark_off_model_edges() {
  const auto skin_point = [&](int v) {
    return model.to_lps(s.theta_z(v, 0), s.theta_z(v, 1), model.r_skin(s.theta_z(v, 0), s.theta_z(v, 1)));
  };
  // An edge is off the model if its mid-edge column is, or if it spans a bony rim.
  for (const auto& poly : s.polygons)
    for (std::size_t i = 0; i < poly.size(); ++i) {
      const auto key = std::minmax(poly[i], poly[(i + 1) % poly.size()]);
      if (bad_edge.count(key) || bad_vertex[key.first] || bad_vertex[key.second]) continue;
      double T_mid = 0;
      std::string why = site_refusal(model, o, 0.5 * (s.theta_z(key.first, 0) + s.theta_z(key.second, 0)),
                                     0.5 * (s.theta_z(key.first, 1) + s.theta_z(key.second, 1)), &T_mid);
      if (why.empty() && trim_rims &&
          across_bony_rim(T[key.first], T[key.second],
                          (skin_point(key.first) - skin_point(key.second)).norm()))
        why = "mesh: the skin mesh crosses a bony rim";
      bad_edge[key] = !why.empty();
      if (!why.empty() && t.why.empty()) t.why = std::move(why);
    }
}

// The polygons kept: those on valid sites, reached from the wound's across shared edges.
bool Trimming::keep_polygons() {
  ok.assign(static_cast<std::size_t>(NP), 1);
  for (int p = 0; p < NP; ++p) {
    const auto& poly = s.polygons[p];
    for (std::size_t i = 0; i < poly.size(); ++i) {
      const auto key = std::minmax(poly[i], poly[(i + 1) % poly.size()]);
      if (bad_vertex[poly[i]] || bad_edge[key]) ok[p] = 0;
      edge_polygons[key].push_back(p);
    }
    if (!ok[p] && s.polygon_layer[p] == 0) return false;  // the stage-1 fill
  }
  for (int v = 0; v < NV; ++v)
    if (wound_vertex[v] && bad_vertex[v]) return false;
  // A layer's polygon stands on the layer below (its inner vertices, those the layer below uses):
  // where that is left out, so is it, so that what lies behind a patch off the model (seen from
  // the wound) goes too and the rim stays one loop, open around the patch.
  int max_layer = 0;
  for (int p = 0; p < NP; ++p) max_layer = std::max(max_layer, s.polygon_layer[p]);
  std::vector<std::vector<int>> by_layer(static_cast<std::size_t>(max_layer) + 1);
  for (int p = 0; p < NP; ++p) by_layer[s.polygon_layer[p]].push_back(p);
  std::vector<char> used_below(static_cast<std::size_t>(NV)), kept_below(static_cast<std::size_t>(NV));
  for (int k = 1; k <= max_layer; ++k) {
    std::fill(used_below.begin(), used_below.end(), 0);
    std::fill(kept_below.begin(), kept_below.end(), 0);
    for (int p : by_layer[k - 1])
      for (int v : s.polygons[p]) {
        used_below[v] = 1;
        if (ok[p]) kept_below[v] = 1;
      }
    for (int p : by_layer[k])
      for (int v : s.polygons[p])
        if (used_below[v] && !kept_below[v]) ok[p] = 0;
  }
  kept.assign(static_cast<std::size_t>(NP), 0);
  std::vector<int> stack;
  for (int p = 0; p < NP; ++p)
    for (int v : s.polygons[p])
      if (ok[p] && wound_vertex[v] && !kept[p]) {
        kept[p] = 1;
        stack.push_back(p);
      }
  while (!stack.empty()) {
    const int p = stack.back();
    stack.pop_back();
    const auto& poly = s.polygons[p];
    for (std::size_t i = 0; i < poly.size(); ++i)
      for (int q : edge_polygons[std::minmax(poly[i], poly[(i + 1) % poly.size()])])
        if (ok[q] && !kept[q]) {
          kept[q] = 1;
          stack.push_back(q);
        }
  }
  return true;
}

bool Trimming::write_surface() {
  // Renumber the vertices the kept polygons use, in their old order (the wound's come first).
  std::vector<int> new_id(static_cast<std::size_t>(NV), -1);
  for (int p = 0; p < NP; ++p)
    if (kept[p])
      for (int v : s.polygons[p]) new_id[v] = 0;
  int n = 0;
  for (int v = 0; v < NV; ++v)
    if (new_id[v] == 0) new_id[v] = n++;
  for (int v = 0; v < NV; ++v)
    if (wound_vertex[v] && new_id[v] < 0) return false;
  // The rim: the kept polygons' border edges other than the wound's, as one loop.
  std::map<int, int> next;
  int n_rim = 0;
  for (int p = 0; p < NP; ++p) {
    if (!kept[p]) continue;
    const auto& poly = s.polygons[p];
    for (std::size_t i = 0; i < poly.size(); ++i) {
      const int a = poly[i], b = poly[(i + 1) % poly.size()];
      const auto key = std::minmax(a, b);
      int users = 0;
      for (int q : edge_polygons[key]) users += kept[q];
      if (users != 1 || wound_edges.count(key)) continue;
      if (!next.emplace(a, b).second) return false;
      ++n_rim;
    }
  }
  if (n_rim == 0) return false;
  SurfaceMesh& out = t.surface;
  const int start = next.begin()->first;
  for (int v = start;;) {
    out.outer_border.push_back(new_id[v]);
    const auto it = next.find(v);
    if (it == next.end()) return false;
    v = it->second;
    if (v == start) break;
    if (static_cast<int>(out.outer_border.size()) > n_rim) return false;
  }
  if (static_cast<int>(out.outer_border.size()) != n_rim) return false;  // several loops
  out.xy_mm.resize(n, 2);
  out.theta_z.resize(n, 2);
  for (int v = 0; v < NV; ++v)
    if (new_id[v] >= 0) {
      out.xy_mm.row(new_id[v]) = s.xy_mm.row(v);
      out.theta_z.row(new_id[v]) = s.theta_z.row(v);
    }
  for (int p = 0; p < NP; ++p) {
    if (!kept[p]) {
      ++t.dropped;
      continue;
    }
    out.polygons.emplace_back();
    for (int v : s.polygons[p]) out.polygons.back().push_back(new_id[v]);
    out.polygon_stage.push_back(s.polygon_stage[p]);
    out.polygon_layer.push_back(s.polygon_layer[p]);
    out.polygon_expanded.push_back(s.polygon_expanded[p]);
    out.n_layers = std::max(out.n_layers, s.polygon_layer[p]);
  }
  if (t.dropped == 0 && t.pulled == 0) return false;  // the failure lies elsewhere
  for (const auto& chain : s.edge_chain) {
    out.edge_chain.emplace_back();
    for (int v : chain) out.edge_chain.back().push_back(new_id[v]);
  }
  for (int v : s.loop_vertex) out.loop_vertex.push_back(new_id[v]);
  out.sutures = s.sutures;
  out.flaps_theta_z = s.flaps_theta_z;
  out.theta_c_deg = s.theta_c_deg;
  out.z_c_mm = s.z_c_mm;
  out.ref_radius_mm = s.ref_radius_mm;
  out.extent_mm = s.extent_mm;
  out.wound_size_mm = s.wound_size_mm;
  out.trimmed_polygons = t.dropped;
  out.pulled_vertices = t.pulled;
  out.quality = surface_quality(out.xy_mm, out.polygons);
  return true;
}

std::optional<Trimmed> trimmed_to_model(SurfaceMesh s, const PatientModel& model,
                                        const ContinuumMeshOptions& o, bool trim_rims) {
  Trimming trimming(std::move(s), model, o, trim_rims);
  trimming.mark_off_model_vertices();
  trimming.mark_off_model_edges();
  if (!trimming.keep_polygons() || !trimming.write_surface()) return std::nullopt;
  return std::move(trimming.t);
}

// For a mesh with columns on tissue without bone or a cavity within the cap (base_tissue): the
// result rests on an interpolated depth and a free base; "" for none.
std::string tissue_base_note(const WoundMesh& w, const PatientModel& model) {
  const auto& tz = w.surface.theta_z;
  int on_tissue = 0;
  for (Eigen::Index v = 0; v < tz.rows(); ++v)
    on_tissue += (model.flags_at(tz(v, 0), tz(v, 1)) & kBaseTissue) != 0;
  if (on_tissue == 0) return {};
  return cat("mesh: ", on_tissue, " of ", tz.rows(), " columns stand on tissue with neither bone "
             "nor an air cavity within the bone cap (base_tissue): their depth is interpolated "
             "from the bone around and their base is free, so the closure is softer than deeper "
             "support would make it (docs/volume.md)");
}

}  // namespace

namespace {

// The automatic extent (mesh_wound() with SurfaceMeshOptions::extent_mm 0): the largest of full,
// 0.75 full, ... whose surface and continuum meshes are valid. An outer layer of the surface
// mesh that folds (a complex border such as a bilobed flap's, grown far out) shrinks the extent
// like skin off the model; a failure of the wound's own first layer does not. Each attempt's
// outcome (a mesh, or the refusal saying why not) decides the next; when every extent fails the
// last refusal is thrown.
class ExtentSearch {
 public:
  ExtentSearch(const WoundBorder& border, const PatientModel& model,
               const SurfaceMeshOptions& surface_options,
               const ContinuumMeshOptions& continuum_options, Reporter* reporter)
      : border_(border), model_(model), surface_options_(surface_options),
        continuum_options_(continuum_options), reporter_(reporter), o_(surface_options) {}

  WoundMesh run();

 private:
  void mesh_full_surface();
  // The warnings of a mesh at `extent` (and across the bony rim `cliff`, if any).
  void finish(WoundMesh& done, double extent, std::string cliff);
  // No extent keeps the whole mesh on the model (a wound beside the eye, near the CT's end, by
  // the nose): the largest extent whose mesh, trimmed to the model, still rings the wound.
  bool trim_to_model(double from);
  void keep_trimmed(Trimmed& t, ContinuumAttempt& attempt, double extent);

  const WoundBorder& border_;
  const PatientModel& model_;
  const SurfaceMeshOptions& surface_options_;
  const ContinuumMeshOptions& continuum_options_;
  Reporter* reporter_;
  WoundMesh w_;
  SurfaceMeshOptions o_;
  std::optional<MeshRefusal> failure_;  // why the last extent tried could not be meshed
  bool surface_ok_ = true, folded_ = false;  // folded: a larger extent's surface mesh folded
  double full_ = 0;
};

// The surface mesh at the full extent; if it folds, the wound's own first layer (which throws
// if the wound itself cannot be meshed) stands in for it until a smaller extent meshes.
void ExtentSearch::mesh_full_surface() {
  MeshOutcome<SurfaceMesh> surface = try_mesh_surface(border_, model_, surface_options_);
  if (surface) {
    w_.surface = std::move(*surface.mesh);
    return;
  }
  failure_ = std::move(surface.refusal);
  surface_ok_ = false;
  folded_ = true;
  SurfaceMeshOptions one = surface_options_;
  one.extent_mm = surface_options_.size_mm;
  w_.surface = mesh_surface(border_, model_, one);  // throws if the wound itself cannot be meshed
  w_.surface.extent_mm = 3.0 * w_.surface.wound_size_mm;
}

void ExtentSearch::finish(WoundMesh& done, double extent, std::string cliff) {
  std::vector<std::string> messages;
  // Tied to the whole-face model, the rim holds nothing: a smaller patch is not a weaker answer.
  if (extent != full_ && continuum_options_.rim != RimCondition::Tied)
    messages.push_back(cat("mesh: the extent was limited to ", std::round(extent * 10) / 10, " mm (",
                           std::round(extent / done.surface.wound_size_mm * 100) / 100,
                           "x the wound's size) to stay on valid cells of the model",
                           folded_ ? " and keep the surface mesh's outer layers from folding" : "",
                           "; the result "
                           "depends more on the rim condition (docs/mesher.md)"));
  if (std::string m = tissue_base_note(done, model_); !m.empty()) messages.push_back(std::move(m));
  if (!cliff.empty())
    messages.push_back(cat("mesh: a bony rim lies under the mesh at every extent down to the "
                           "mesh size (", cliff, "); it is meshed across: the elements there are "
                           "sheared and model the tissue over both bone levels as one column "
                           "(docs/mesher.md)"));
  for (const std::string& m : messages) {
    done.continuum.mesh.warnings.push_back(m);
    warn(reporter_, m);
  }
}

bool ExtentSearch::trim_to_model(double from) {
  // The extents of the search, largest first: a clamped rim (the 1992 patch) is best kept far
  // from the wound. A rim tied into the whole face holds nothing, so there the smallest trimmed
  // mesh that rings the wound is taken: a large one, trimmed around the eye or the nose, keeps
  // arms of skin reaching along the valid cells between them, far out (at a 4 mm mesh size a
  // cheek ellipse below the eye kept a 100 mm arm to the temple, and the whole face's region,
  // which reaches 5 mm beyond the patch, grew to 139 mm: 121,000 tetrahedra instead of 18,000).
  std::vector<double> extents;
  for (double extent = from; extent >= surface_options_.size_mm; extent *= 0.75)
    extents.push_back(extent);
  if (continuum_options_.rim == RimCondition::Tied) std::reverse(extents.begin(), extents.end());
  // First with the bony rims trimmed too; then, as for a whole mesh, meshed across.
  for (const bool trim_rims : {true, false})
    for (const double extent : extents) {
      o_.extent_mm = extent;
      MeshOutcome<SurfaceMesh> surface = try_mesh_surface(border_, model_, o_);
      if (!surface) continue;  // folded: a smaller extent may not
      std::optional<Trimmed> t =
          trimmed_to_model(std::move(*surface.mesh), model_, continuum_options_, trim_rims);
      if (!t) continue;
      ContinuumAttempt attempt =
          attempt_continuum(t->surface, model_, continuum_options_, !trim_rims);
      if (!attempt.mesh) continue;  // off the model, or an inverted element at the trimmed border
      keep_trimmed(*t, attempt, extent);
      return true;
    }
  return false;
}

void ExtentSearch::keep_trimmed(Trimmed& t, ContinuumAttempt& attempt, double extent) {
  w_.surface = std::move(t.surface);
  w_.continuum = std::move(*attempt.mesh);
  std::string first = t.why.substr(0, t.why.find(';'));
  if (first.rfind("mesh: ", 0) == 0) first.erase(0, 6);
  const std::string m = cat(
      "mesh: the skin mesh (extent ", std::round(extent * 10) / 10, " mm) was trimmed to "
      "the model where it reached cells it cannot carry (first: ", first, "): ",
      t.dropped, " polygons left out",
      t.pulled > 0 ? cat(", ", t.pulled, t.pulled == 1 ? " first-layer vertex" :
                         " first-layer vertices", " pulled back towards the wound")
                   : std::string(),
      "; the rim follows the valid cells there and is held like the rest of the rim, so "
      "the result depends more on the rim condition (docs/mesher.md, \"Trimmed to the "
      "model\")");
  // Tied to the whole-face model, the trimmed rim holds nothing either.
  if (continuum_options_.rim != RimCondition::Tied) {
    w_.continuum.mesh.warnings.push_back(m);
    warn(reporter_, m);
  }
  finish(w_, full_, std::move(attempt.cliff));  // the message above gives the extent
}

WoundMesh ExtentSearch::run() {
  mesh_full_surface();
  full_ = w_.surface.extent_mm;
  // The largest extent whose mesh is valid but for a bony rim under it, meshed across the rim:
  // used when no smaller extent stays short of the rim (the cheek over the maxilla, where the
  // bone's depth steps wherever the mesh reaches).
  std::optional<WoundMesh> across;
  double across_extent = 0;
  std::string across_cliff;
  for (double extent = full_;; extent *= 0.75) {
    if (reporter_) reporter_->check_cancelled();  // between extents: each is a whole mesh
    if (extent != full_) {
      o_.extent_mm = extent;
      MeshOutcome<SurfaceMesh> surface = try_mesh_surface(border_, model_, o_);
      surface_ok_ = surface.mesh.has_value();
      if (surface_ok_) {
        w_.surface = std::move(*surface.mesh);
      } else {
        failure_ = std::move(surface.refusal);
        folded_ = true;
      }
    }
    if (surface_ok_) {
      // Until a mesh across a rim is kept, a rim is meshed across (and the mesh kept if no
      // smaller extent avoids it); after that a rim counts as off the model.
      ContinuumAttempt attempt = attempt_continuum(w_.surface, model_, continuum_options_, !across);
      // An inverted element of a whole mesh is not the extent's doing: the caller's to fix.
      if (!attempt.mesh && attempt.refusal.kind == MeshRefusal::Kind::Inverted)
        throw_refusal(attempt.refusal);
      if (attempt.mesh && attempt.cliff.empty()) {
        w_.continuum = std::move(*attempt.mesh);
        finish(w_, extent, {});
        return std::move(w_);
      }
      if (attempt.mesh) {
        across = WoundMesh{w_.surface, std::move(*attempt.mesh)};
        across_extent = extent;
        across_cliff = std::move(attempt.cliff);
      } else {
        failure_ = std::move(attempt.refusal);
      }
    }
    if (extent * 0.75 < surface_options_.size_mm) {
      if (!across && trim_to_model(full_)) return std::move(w_);
      if (!across) throw_refusal(*failure_);
      finish(*across, across_extent, across_cliff);
      return std::move(*across);
    }
  }
}

}  // namespace

WoundMesh mesh_wound(const WoundBorder& border, const PatientModel& model,
                     const SurfaceMeshOptions& surface_options,
                     const ContinuumMeshOptions& continuum_options, Reporter* reporter) {
  if (surface_options.extent_mm > 0) {
    WoundMesh w;
    w.surface = mesh_surface(border, model, surface_options);
    w.continuum = mesh_continuum(w.surface, model, continuum_options);
    if (std::string m = tissue_base_note(w, model); !m.empty()) {
      warn(reporter, m);
      w.continuum.mesh.warnings.push_back(std::move(m));
    }
    return w;
  }
  return ExtentSearch(border, model, surface_options, continuum_options, reporter).run();
}

}  // namespace caps::mesher

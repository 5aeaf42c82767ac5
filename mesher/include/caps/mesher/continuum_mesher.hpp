#pragma once
/// @brief The continuum mesher (paper section 6): extrudes a surface mesh from the skin to the
/// bone in layers of 20-node hexahedra (quads) and 15-node wedges (triangles), with suture pairs
/// and fixed nodes, ready for solve().
///
/// Depth: each surface site (vertex or edge midpoint, at (theta, z)) gets a column of nodes on the
/// line from the skin point r_skin(theta, z) towards the axis, down to r_skin - thickness(theta, z)
/// (the measured bone; the paper used a constant depth, `constant_thickness_mm`). Layer k has the
/// thickness fraction grading^k / sum_j grading^j. Vertex columns carry corner nodes at every layer
/// interface and a centre node in the middle of every layer; edge columns carry the mid-edge nodes
/// at every interface. Elements of one column share those nodes, so neighbouring elements share
/// faces and mid-edge nodes.
/// Tissue layers (TissueLayers::Measured; docs/fem.md, "Measured layers"): the element layers
/// follow the model's measured skin/fat and fat/deep interfaces instead of fixed fractions: each
/// column's depths come from the layer maps at its site (bilinear, like the thickness), every
/// tissue layer (dermis, subcutaneous fat, deep tissue) gets the same number of element layers
/// and its own material (element layer id 0 dermis, 1 fat, 2 deep). A tissue layer thinner than
/// min_tissue_layer_mm (the fat where none was seen) is widened to it at the expense of the
/// thickest one; the elements of such a fat layer whose corner columns mostly had no fat of that
/// thickness carry the deep tissue's material (no fat is there).
/// Sutures: for each suture ((a,b),(c,d)) the nodes along the two sides (border edges, or runs of
/// them, which the surface mesher gave matching nodes by arc length) are paired at every depth
/// (corners, mid-edge and centre nodes); the shared point of a closed corner is skipped.
/// Fixed nodes: every bottom node that is not sutured (the bony support), not within
/// `undermine_mm` of the wound's border and not under a flap the plan raises; with RimCondition::Fixed also every node on the outer rim
/// (the far field is clamped), with Free the rim is traction free.

#include <cmath>
#include <Eigen/Core>
#include <string>
#include <vector>

#include "caps/core/reporter.hpp"
#include "caps/fem/material.hpp"
#include "caps/fem/mesh.hpp"
#include "caps/core/error.hpp"
#include "caps/mesher/surface_mesher.hpp"

namespace caps::mesher {

/// What holds the outer rim of the mesh. Fixed: clamped (the 1992 patch); Free: traction free;
/// Tied: joined to the patient's whole-face tissue model (closure/face_domain.hpp), so the rim
/// decides nothing: the mesher leaves it free, lists it (ContinuumMesh::rim_nodes) for the tie,
/// and a limited extent is no longer a warning.
enum class RimCondition { Fixed, Free, Tied };

/// What holds the base of undermined tissue and raised flaps (the freed bottom nodes).
/// Slide: it rests on the deep tissue and slides over it (held along the base's normal only,
/// averaged over 3 mm of the mesh's bottom surface; the nodes a suture ties at the wound's floor
/// slide as one; Mesh::sliding); Free: it is free in all directions (the 1992 model), so it may
/// lift off or sink into the bone when the closure compresses it.
enum class BaseCondition { Slide, Free };

/// The spring that holds a sliding base along the bone's normal, per unit of the tissue's
/// stiffness (MPa) and of its height above the base (mm): stiff enough that the support gives
/// way by about 1e-6 mm under the closing forces (the patch's freed base; the whole face's
/// undermined tissue, closure/face_domain.cpp).
inline constexpr double kSlidingStiffness = 1e5;

/// "slide" / "free".
const char* base_condition_name(BaseCondition base);
/// Parses "slide" / "free"; throws InvalidInput otherwise.
BaseCondition parse_base_condition(const std::string& name);

/// How the soft tissue between skin and bone is layered.
/// Uniform: one material (ContinuumMeshOptions::material) in n_layers element layers at fixed
/// fractions of the depth (the 1992 model). Measured: the model's measured tissue layers, each
/// with its own material (refused when the model has no layer maps). Auto: Measured where the
/// model has layer maps and at least a quarter of the surface mesh's vertices lie on cells whose
/// layers were measured (no layer flag), else Uniform.
enum class TissueLayers { Auto, Uniform, Measured };

/// "auto" / "uniform" / "measured".
const char* tissue_layers_name(TissueLayers tissue);
/// Parses "auto" / "uniform" / "measured"; throws InvalidInput otherwise.
TissueLayers parse_tissue_layers(const std::string& name);

/// Element layer ids (Element::layer, Mesh::materials) of the measured tissue layers.
inline constexpr int kDermisLayer = 0, kFatLayer = 1, kDeepLayer = 2;

/// "fixed" / "free".
const char* rim_condition_name(RimCondition rim);
/// Parses "fixed" / "free"; throws InvalidInput otherwise.
RimCondition parse_rim_condition(const std::string& name);

struct ContinuumMeshOptions {
  /// Element layers between skin and bone, >= 1. Measured tissue layers: each of the three gets
  /// max(1, round(n_layers / 3)) of them.
  int n_layers = 2;
  double grading = 1.0;         ///< uniform: thickness ratio of each layer to the one above, > 0
  RimCondition rim = RimCondition::Fixed;
  double min_thickness_mm = 0.5;  ///< refuse sites with less soft tissue than this
  /// > 0: a constant depth (mm) as in the 1992 paper, instead of the model's thickness map.
  double constant_thickness_mm = 0;
  /// Undermining (mm): the base of the tissue within this distance of the wound's border (in
  /// the skin's plane) is freed from the bone, as a surgeon undermines the wound's edges to
  /// close it. Default 10 mm: about the width of the usual excision, the lower end of the 1-2 cm
  /// surgeons undermine around an ellipse (docs/fem.md, "Undermining and raised flaps"). 0 frees
  /// only the sutured columns (the paper), which makes the freed strip one element wide and the
  /// closing force depend on the mesh size (docs/mesher.md). The plan's flaps are freed over
  /// their whole area whatever this is.
  double undermine_mm = 10;
  BaseCondition base = BaseCondition::Slide;  ///< the freed base: slides on the deep tissue or is free
  /// Uniform: the material of every element layer ("skin"; the preset data/materials/skin.json).
  std::shared_ptr<const fem::Material> material = fem::default_skin();
  /// Uniform (default) or measured tissue layers (Auto: measured when the model has them).
  /// Measured layers are not the default yet: why, and on which plans, is in docs/fem.md
  /// ("Measured layers").
  TissueLayers tissue = TissueLayers::Uniform;
  /// Measured: the thinnest a tissue layer is meshed (mm; at most a quarter of the column).
  double min_tissue_layer_mm = 0.5;
  /// Measured: the materials of the dermis (layer kDermisLayer), the subcutaneous fat and the
  /// deep tissue (muscle, fascia); presets data/materials/dermis.json, fat.json, deep.json.
  std::shared_ptr<const fem::Material> dermis = fem::default_dermis();
  std::shared_ptr<const fem::Material> fat = fem::default_fat();
  std::shared_ptr<const fem::Material> deep = fem::default_deep();
  /// When set, the material of element layer 0, the skin's surface (the measured dermis, or the
  /// uniform model's top element layer), instead of `dermis` or `material`: e.g.
  /// default_goh_skin(), the fibre-reinforced skin over the neo-Hookean tissue (`--material goh`).
  std::shared_ptr<const fem::Material> surface_material;
  /// How the mesh's Wedge15 elements are integrated (fem::Mesh::wedge_rule): caps's 21 points,
  /// or CalculiX's 9 for a mesh.inp that ccx solves to the same answer.
  fem::WedgeRule wedge_rule = fem::WedgeRule::Full;
};

/// The continuum mesh and where its nodes came from.
struct ContinuumMesh {
  fem::Mesh mesh;
  Eigen::MatrixX2d node_theta_z;      ///< #N×2 (theta deg, z mm) of each node's column
  Eigen::VectorXd node_level;         ///< #N depth level: 0 skin .. n_layers bone (k + 0.5 centre)
  std::vector<int> element_polygon;   ///< element -> surface polygon
  std::vector<int> skin_node;         ///< surface vertex -> its node on the skin
  /// The nodes of the outer rim's columns (vertex and edge columns, skin to bone), sorted; those
  /// the rim condition holds when Fixed, those tied to the whole-face model when Tied.
  std::vector<int> rim_nodes;
  int n_layers = 0;
  /// The tissue layering used (Uniform or Measured; Auto is resolved).
  TissueLayers tissue = TissueLayers::Uniform;
  /// Measured: the node levels of the skin/fat and the fat/deep interfaces (-1 when uniform).
  int fat_top_level = -1, fat_bottom_level = -1;
  /// Measured: vertex columns whose fat was widened to min_tissue_layer_mm.
  int widened_fat_columns = 0;
  double min_thickness_mm = 0, max_thickness_mm = 0;  ///< over the mesh's sites
  double min_jacobian = 0;  ///< smallest det J over all Gauss points (mm^3 per unit volume)
};

/// How a continuum mesh of `surface` on `model` divides the soft tissue in depth: its element
/// layers and the depths of their interfaces in each column. The mesher builds its columns with
/// it, and the cross-section picture draws the same interfaces.
class LayerStack {
 public:
  /// Resolves options.tissue (Auto: measured where at least a quarter of the surface's vertices
  /// lie on cells whose layers were measured); throws InvalidParameter for Measured on a model
  /// without layer maps.
  LayerStack(const SurfaceMesh& surface, const PatientModel& model,
             const ContinuumMeshOptions& options);

  bool measured() const { return per_ > 0; }
  int n_layers() const { return static_cast<int>(fractions_.size()) - 1; }
  /// Measured: element layers in each tissue layer (dermis, fat, deep); 0 when uniform.
  int per_tissue_layer() const { return per_; }

  /// The depths (mm below the skin, 0 .. T) of the n_layers() + 1 element-layer interfaces of a
  /// column of soft-tissue thickness T (mm) at (theta deg, z mm), written to `depths`. Uniform:
  /// fixed fractions of T, each layer `grading` times the one above. Measured: the model's
  /// dermis, fat and deep thicknesses scaled to T, a layer thinner than min_tissue_layer_mm
  /// (at most T/4) widened at the thickest one's expense; *no_fat (if given) tells that the fat
  /// was that thin.
  void depths(double theta_deg, double z_mm, double T_mm, std::vector<double>& depths,
              bool* no_fat = nullptr) const;

 private:
  const PatientModel* model_;
  double min_tissue_layer_mm_;
  int per_ = 0;
  std::vector<double> fractions_;  // uniform: interface depth / T
};

/// Extrudes `surface` through the patient model. Throws InvalidInput naming theta and z where a
/// site lies outside the model's z range, on an invalid cell (!flags_valid(flags_at)), where the
/// thickness is below `min_thickness_mm`, or where an element's Jacobian is not positive at a
/// Gauss point. Bottom nodes over an air cavity (kBaseCavity) or deeper tissue (kBaseTissue) get
/// no support.
ContinuumMesh mesh_continuum(const SurfaceMesh& surface, const PatientModel& model,
                             const ContinuumMeshOptions& options = {});

/// mesh_continuum() returning a site off the model or a bony rim under the mesh (OffModel) and
/// an inverted element (Inverted) as its refusal, with the place, instead of throwing; bad
/// options and a suture between sides of different node counts still throw InvalidInput,
/// measured layers on a model without layer maps InvalidParameter.
MeshOutcome<ContinuumMesh> try_mesh_continuum(const SurfaceMesh& surface, const PatientModel& model,
                                              const ContinuumMeshOptions& options = {});

/// The smallest Jacobian determinant of each element over its Gauss points (#E).
Eigen::VectorXd min_element_jacobians(const fem::Mesh& mesh);

/// The whole mesher: surface mesh, then continuum mesh.
struct WoundMesh {
  SurfaceMesh surface;
  ContinuumMesh continuum;
};
/// A mesh node would stand where the model cannot carry it (an invalid cell, outside the model's
/// z range, or tissue thinner than the minimum). The message names theta and z.
class OffModelError : public InvalidParameter {
 public:
  explicit OffModelError(const std::string& message, double theta_deg = NAN, double z_mm = NAN)
      : InvalidParameter(message), theta_deg(theta_deg), z_mm(z_mm) {}
  double theta_deg, z_mm;  ///< the column that could not stand (NAN where not known)
};

/// Throws a mesher's refusal as mesh_surface() and mesh_continuum() do: OffModel as
/// OffModelError, the others as InvalidParameter, with its message.
[[noreturn]] void throw_refusal(const MeshRefusal& refusal);

/// Rows of the model's grid kept free at its top and bottom ends: the renderer stitches the
/// displaced skin into the range image with a margin of 3 rows around the mesh (render/
/// skin_surface.cpp), so a mesh closer to the ends could be solved but not drawn.
inline constexpr int kEndRowsKeptFree = 4;

/// The steepest step of the tissue depth between neighbouring columns of a continuum mesh: depth
/// difference over their distance on the skin (2: the bone surface under the skin slopes up to
/// about 63 deg from the skin's). A steeper step is a bony rim (the orbit's, a sinus's), which
/// the mesher treats as off the model (continuum_mesher.cpp).
inline constexpr double kMaxDepthSlope = 2.0;

/// Both stages. With surface_options.extent_mm == 0 (automatic: 3 x the wound's size) the extent
/// shrinks, in steps of 0.75, down to 1 x the mesh size, while the outer layers would leave the
/// model's valid cells, and a warning gives the extent reached; a given extent is never changed.
/// A wound whose own site is not valid is refused (OffModelError naming the place). The extents
/// are tried by their outcomes (try_mesh_surface(), try_mesh_continuum()); when none gives a
/// mesh the last refusal is thrown (throw_refusal()).
WoundMesh mesh_wound(const WoundBorder& border, const PatientModel& model,
                     const SurfaceMeshOptions& surface_options = {},
                     const ContinuumMeshOptions& continuum_options = {},
                     Reporter* reporter = nullptr);

}  // namespace caps::mesher

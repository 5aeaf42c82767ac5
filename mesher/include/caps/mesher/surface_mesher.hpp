#pragma once
/// @brief The surface mesher (paper section 6, after Chae and Bathe): a mesh of quadrilaterals and
/// triangles grown outward from the wound's border over the skin, in (theta deg, z mm).
///
/// Work space: a local tangent plane around the wound, x = (theta - theta_c) * pi/180 * R_ref
/// (mm of arc at the reference radius R_ref = r_skin at the wound's centre), y = z - z_c (mm), so
/// angles and lengths mean what they say. The border loop runs with the hole on its left
/// (counter-clockwise in (x, y)); a clockwise loop is handled by mirroring internally. A plain
/// incision has zero area: its two lips are distinct vertices at the same place.
///   stage 1  while a border vertex is concave by more than t1 (hole angle > 180 + t1), add the
///            triangle (v_{i+2}, v_{i+1}, v_i) and drop v_{i+1}; a region so filled whose
///            triangles are poor (a ladder across a large flap) is then re-triangulated with
///            interior points, its boundary kept edge for edge;
///   stage 2  add a layer of quadrilaterals of thickness l at a time; a vertex whose hole angle is
///            below t2 is "expanded" into a fan of corner quadrilaterals (one as in the paper,
///            two at a slit's end, where the hole angle is 0);
///   growth   layers grow in thickness (at most `growth` times the previous one, never thicker
///            than the border's median edge) and new border edges longer than `split_ratio` times
///            the layer thickness are split, with one triangle per split, until the layers reach
///            `extent_mm` from the wound.

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "caps/plan/plan.hpp"

namespace caps {
class PatientModel;
}

namespace caps::mesher {

/// The wound border the plan layer hands to the mesher (plan::wound_border()): the hole's border
/// loop in (theta deg, z mm), excision offsets applied, coincident twins allowed; and the border
/// edges (a,b) sutured to (c,d), a meeting c and b meeting d, a shared point being a closed corner.
using WoundBorder = plan::WoundBorder;

struct SurfaceMeshOptions {
  double t1_deg = 30;        ///< stage 1: fill concavities deeper than this (paper default 30)
  /// Stage 1: a region of stage-1 triangles whose smallest corner is below this (deg, 0..20.7)
  /// is re-triangulated with interior points (constrained Delaunay refinement, border nodes and
  /// the front left for stage 2 unchanged); 0 keeps stage 1's triangles as the paper builds them.
  double stage1_min_angle_deg = 20;
  double t2_deg = 90;        ///< stage 2: expand vertices whose hole angle is below this
  double size_mm = 2;        ///< target edge length on the border and first layer thickness l1
  /// Distance from the wound to the outer rim (mm); <= 0 means 3 x the wound's size (its
  /// largest extent), the default measured in docs/mesher.md.
  double extent_mm = 0;
  double growth = 1.25;      ///< largest ratio of one layer's thickness to the previous one
  double split_ratio = 1.8;  ///< split new border edges longer than this x the layer thickness
  int max_layers = 200;      ///< safety limit
};

/// Shape statistics of a surface mesh, in the local plane (mm, degrees).
struct SurfaceQuality {
  double min_angle_deg = 0, max_angle_deg = 0;  ///< over all polygon corners
  double max_aspect_ratio = 0;  ///< longest / shortest edge of a polygon
  double mean_aspect_ratio = 0;
  int n_quads = 0, n_triangles = 0;
};

/// The surface mesh. Polygons run counter-clockwise in (x, y) = (arc mm, z mm).
struct SurfaceMesh {
  Eigen::MatrixX2d xy_mm;     ///< #V×2 local plane, mm
  Eigen::MatrixX2d theta_z;   ///< #V×2 (theta deg, z mm); theta unwrapped around theta_c
  std::vector<std::vector<int>> polygons;  ///< 3 or 4 vertex ids each
  std::vector<int> polygon_stage;  ///< 1 = stage-1 triangle, 2 = layer polygon
  std::vector<int> polygon_layer;  ///< 0 for stage 1, k >= 1 for the k-th layer
  std::vector<int> polygon_expanded;  ///< 1 for the corner polygons of an expanded vertex
  /// Border chain of each loop edge i (loop point i to i+1): vertex ids from i to i+1 inclusive.
  std::vector<std::vector<int>> edge_chain;
  std::vector<int> loop_vertex;   ///< loop point i -> vertex id (distinct for twins)
  std::vector<int> outer_border;  ///< the rim, vertex ids in order
  std::vector<std::array<int, 4>> sutures;  ///< copied from the WoundBorder
  /// The flaps' outlines, (theta deg, z mm) unwrapped like theta_z (from the WoundBorder).
  std::vector<std::vector<Eigen::Vector2d>> flaps_theta_z;
  double theta_c_deg = 0, z_c_mm = 0, ref_radius_mm = 0;
  double extent_mm = 0;      ///< the extent actually used
  double wound_size_mm = 0;  ///< largest extent of the loop
  int n_layers = 0;
  /// Polygons of the grown layers left out where they reached cells the model cannot carry (the
  /// eye, the CT's end rows, skin its cylindrical image does not hold): the rim follows the
  /// valid cells there (mesh_wound(), docs/mesher.md "Trimmed to the model"); 0 for a whole mesh.
  int trimmed_polygons = 0;
  int pulled_vertices = 0;  ///< first-layer vertices pulled back towards the wound onto the model
  SurfaceQuality quality;

  int n_vertices() const { return static_cast<int>(xy_mm.rows()); }
};

/// Why a mesher's attempt gave no mesh: what went wrong, where and the message (a template
/// naming parameters in braces, as InvalidParameter's). A caller with room to mesh less (a
/// smaller extent, a trimmed mesh) tries again; the throwing mesh_surface() and
/// mesh_continuum() throw it as InvalidParameter (OffModel as OffModelError: throw_refusal()).
struct MeshRefusal {
  enum class Kind {
    Folded,     ///< a layer of the surface mesh folds over or overlaps itself
    Unreached,  ///< the surface mesh's layers (max_layers) do not reach the extent
    OffModel,   ///< a column would stand where the model cannot carry it, or across a bony rim
    Inverted    ///< an element of the continuum mesh is inverted or degenerate
  };
  Kind kind = Kind::Folded;
  double theta_deg = NAN, z_mm = NAN;  ///< the place (NAN for Unreached)
  std::string message;
};

/// A mesher's outcome: the mesh, or the refusal that says why there is none.
template <class M>
struct MeshOutcome {
  std::optional<M> mesh;
  MeshRefusal refusal;  ///< set when there is no mesh
  explicit operator bool() const { return mesh.has_value(); }
};

/// Meshes the skin around the wound. `model` supplies the reference radius (r_skin at the
/// wound's centre). Throws InvalidInput for a loop with fewer than 2 points, non-finite or
/// repeated neighbouring points, suture edges that are not loop edges, or layers that overlap
/// (the message names theta and z).
SurfaceMesh mesh_surface(const WoundBorder& border, const PatientModel& model,
                         const SurfaceMeshOptions& options = {});

/// The same with an explicit reference radius (mm), for tests and for flat (theta, z) planes.
SurfaceMesh mesh_surface(const WoundBorder& border, double ref_radius_mm,
                         const SurfaceMeshOptions& options = {});

/// mesh_surface() returning a layer that folds over or overlaps itself (Folded) and layers that
/// do not reach the extent (Unreached) as its refusal instead of throwing InvalidParameter; bad
/// input still throws InvalidInput.
MeshOutcome<SurfaceMesh> try_mesh_surface(const WoundBorder& border, const PatientModel& model,
                                          const SurfaceMeshOptions& options = {});
MeshOutcome<SurfaceMesh> try_mesh_surface(const WoundBorder& border, double ref_radius_mm,
                                          const SurfaceMeshOptions& options = {});

/// Shape statistics of a set of polygons in the plane.
SurfaceQuality surface_quality(const Eigen::MatrixX2d& xy_mm,
                               const std::vector<std::vector<int>>& polygons);

}  // namespace caps::mesher

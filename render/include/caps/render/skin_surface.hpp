#pragma once
/// @brief The displacement-mapped skin (paper section 4): the skin faces of the finite elements
/// are subdivided into micropolygons that carry the full-resolution range and colour data, and
/// the rest of the head is the model's range mesh, stitched to the micropolygons without cracks.
///
/// For each element whose top face (nodes 0-3 of a Hex20, 0-2 of a Wedge15, with their mid-edge
/// nodes; a Tet10 has no top face and is never a skin element) lies on the skin, the face is
/// subdivided n × n in its natural coordinates. At each micropolygon vertex (xi, eta):
///   x_face = sum_a N_a(xi, eta, -1) X_a           the element's face (its shape functions)
///   (theta, z) of x_face; s = skin_point(theta, z), colour = color_at(theta, z)
///   d = s - x_face                                 the range offset, kept per vertex
///   pre  = x_face + d  (= s)
///   post = x_face + u(xi, eta) + d,  u = sum_a N_a U_a   (the FE displacement)
/// Vertices on an edge shared by two elements are welded (one vertex per edge point), so the
/// micropolygon skin has no cracks between elements.
///
/// Outside the mesh the skin is the range mesh: one vertex per (theta, z) sample, two triangles
/// per cell, periodic in theta, closed at the first and last rows by a fan to the axis. Cells
/// near the mesh's footprint (touching it, dilated by one cell, holes filled) are left out, and
/// the annulus between the staircase border of those cells and the mesh's outer rim is a
/// constrained Delaunay triangulation in (theta, z) of the vertices of both and of the grid
/// vertices between them: every seam edge is shared by two triangles, so the seam cannot crack,
/// whatever the rim does, and no seam triangle folds. The wound
/// (the hole of an excision) is filled by an ear-clipped triangulation of its border's
/// micropolygon vertices: pre-operatively it is the skin to be removed; when the wound closes
/// its border vertices meet and the fill collapses onto the suture line, covering the small
/// mismatch of the two lips' range offsets.
///
/// Pre and post share one triangle list and one colour per vertex (so images, animations and
/// morph targets can blend them); only the positions and the shading normals differ. Every
/// vertex is shaded with one smooth normal field of the drawn range (normal_pre), turned after
/// the closure only where its neighbourhood moved (normal_post), so the patch shades exactly as
/// the skin around it wherever nothing moved.

#include <Eigen/Core>
#include <vector>

#include "caps/core/mesh.hpp"
#include "caps/fem/mesh.hpp"
#include "caps/fem/solve.hpp"
#include "caps/surface/feature_lines.hpp"

namespace caps {
class PatientModel;
}

namespace caps::render {

struct DrawnSkin;

/// What produced a triangle of the skin.
/// (Isosurface: the smoothed isosurface drawn in the range image's undercuts, DrawnSkin.)
enum class SkinPart : int { Range = 0, Micropolygon = 1, Seam = 2, WoundFill = 3, Isosurface = 4 };

/// The pre- and post-operative skin, one topology.
struct SkinSurfaces {
  TriMesh pre;                    ///< V #V×3 (LPS, mm), F #F×3 outward (counter-clockwise)
  TriMesh post;                   ///< same F, displaced V
  Eigen::MatrixX3d color;         ///< #V×3 RGB in [0, 1]
  Eigen::MatrixX2d theta_z;       ///< #V×2 (theta deg, z mm) where each vertex sampled the model
  Eigen::MatrixX3d range_offset_mm;  ///< #V×3 d = skin - x_face (zero off the mesh)
  Eigen::VectorXi vertex_element;    ///< #V the element a micropolygon vertex came from, else -1
  /// #V×2 natural coordinates (xi, eta) of a micropolygon vertex on its element's top face
  /// (zeta = -1; x_face = sum_a N_a(xi, eta, -1) X_a); 0 where vertex_element is -1
  Eigen::MatrixX2d vertex_natural;
  /// #V×3 unit shading normals of pre (LPS): the drawn range surface's smooth normal field at
  /// each vertex's (theta, z), the same for the range mesh, the seam and the micropolygons, so the
  /// patch shades exactly as the skin around it. Empty: use vertex_normals(pre).
  Eigen::MatrixX3d normal_pre;
  /// #V×3 unit shading normals of post: unit(normal_pre + m_post - m_pre), m = vertex_normals() of
  /// the mesh, so equal to normal_pre wherever nothing of the vertex's one-ring moved. Empty: use
  /// vertex_normals(post).
  Eigen::MatrixX3d normal_post;
  std::vector<SkinPart> face_part;   ///< #F
  std::vector<int> skin_elements;    ///< elements whose top face lies on the skin
  int n_micropolygon_vertices = 0;
  /// The micropolygons' outer rim: a loop of their vertices, counter-clockwise in (theta, z).
  /// Beyond it, in a closure in the whole face, the skin follows the tissue model's skin nodes;
  /// within kSeamBlendMm of it the rim's displacement carries on into theirs (seam_field()), and
  /// the tension map goes over into theirs within kSeamBlendInsideMm inside it.
  std::vector<int> rim_vertices;
  /// The cells q = k n_theta + j (0 <= j < n_theta, 0 <= k < n_z - 1) of the model's range mesh
  /// left out under the mesh's footprint (where the micropolygons, the wound fill and the seam
  /// replace the range image), sorted.
  std::vector<int> replaced_cells;
  Eigen::Vector3d mesh_centre_lps = Eigen::Vector3d::Zero();  ///< centroid of the skin faces
  double mesh_radius_mm = 0;  ///< largest distance of a micropolygon vertex from the centre
};

/// A face lies on the skin when each of its nodes is within this distance (mm) of the range
/// surface along the model's radial ray.
inline constexpr double kOnSkinToleranceMm = 1e-4;

/// How far beyond the patch's rim its displacement and fields carry on into the whole face's
/// (mm; surface::blend_across_seam()): about two of the tissue model's facets on the face, so the
/// seam shows no edge where the two discretisations differ.
inline constexpr double kSeamBlendMm = 3.0;
/// How far inside the patch's rim a nodal field on the skin (nodal_field_on_skin(): the tension
/// map) goes over from the tissue model's field at the rim to the patch's own: its outermost
/// elements' field is kinked by the tie, and the map would show the rim as a ring of teeth.
inline constexpr double kSeamBlendInsideMm = 1.5;

/// How much of the head displaced_skin() builds.
enum class SkinExtent {
  WholeHead,  ///< the range mesh of the whole head around the patch, closed at both ends
  Patch       ///< only the micropolygons, the wound fill and the seam (with the range vertices
              ///< the seam uses): the rest is the model's range mesh without replaced_cells,
              ///< which a viewer already draws (the planner page); a fraction of the time
};

/// The elements whose top face lies on the skin (each face node within kOnSkinToleranceMm).
std::vector<int> skin_elements(const PatientModel& model, const fem::Mesh& mesh);

/// The subdivisions (1..64) that make the micropolygons of the longest skin-face edge no longer
/// than the model's finest sample spacing (dz, or dtheta as arc at the skin), so the
/// micropolygons carry the full resolution of the range data (paper section 4).
int full_resolution_subdivisions(const PatientModel& model, const fem::Mesh& mesh);

/// Builds the pre- and post-operative skin of `mesh` on `model` with `n_subdivisions` (>= 1)
/// micropolygons along each element edge. `displacement_mm` (#N×3, mm) or null for none (then
/// post == pre). Throws InvalidInput if no element face lies on the skin, if the displacement has
/// the wrong size or is not finite, or if the mesh reaches the first or last row of the model.
/// `drawn` (null: `model` itself) is the skin drawn (drawn_skin.hpp): its range, a model on the
/// same grid whose r_skin and colour the micropolygons and the range mesh sample (resampled from
/// the smoothed isosurface, slice terraces filtered), and the isosurface's triangles that replace
/// the range cells in undercuts (outside the mesh's footprint; SkinPart::Isosurface, not stitched
/// to the range cells but overlapping them, so the skin is then no longer one closed manifold).
/// Within 3 cells of the footprint the range mesh is drawn instead (the seam joins the patch to
/// range vertices), but where the range image's rays graze the skin.
/// The skin faces are still found on `model`. `extent` Patch builds the part around the mesh
/// only (no SkinPart::Range or Isosurface faces; the seam's range vertices are the model's
/// samples, as in WholeHead, so the patch fits the range mesh without its replaced_cells).
SkinSurfaces displaced_skin(const PatientModel& model, const fem::Mesh& mesh,
                            const Eigen::MatrixX3d* displacement_mm, int n_subdivisions,
                            const DrawnSkin* drawn = nullptr,
                            SkinExtent extent = SkinExtent::WholeHead);

/// The same with a solve result (null: no displacement).
SkinSurfaces displaced_skin(const PatientModel& model, const fem::Mesh& mesh,
                            const fem::SolveResult* result, int n_subdivisions,
                            const DrawnSkin* drawn = nullptr,
                            SkinExtent extent = SkinExtent::WholeHead);

/// Area-weighted unit vertex normals of a mesh (V #V×3, F #F×3 counter-clockwise outward); a
/// vertex in no non-degenerate triangle gets a zero row.
Eigen::MatrixX3d vertex_normals(const TriMesh& mesh);

/// The drawn range surface's smooth normal field at (theta deg, z mm) rows of `theta_z` (#P×2):
/// central-difference normals of skin.r_skin at the grid samples, interpolated bilinearly and
/// normalised (the normals displaced_skin() gives the pre-operative skin). #P×3 unit, LPS.
Eigen::MatrixX3d skin_normal_field(const PatientModel& skin, const Eigen::MatrixX2d& theta_z);

/// The shading normals of the skin blended pre + t (post - pre), t in [0, 1]: unit((1 - t)
/// normal_pre + t normal_post), or vertex_normals() of the blended mesh when the skin carries no
/// normals. #V×3, LPS.
Eigen::MatrixX3d shading_normals(const SkinSurfaces& skin, double t);

/// A field on the skin around a patch closed in the whole face: `far` (the field of the tissue
/// model's skin nodes) carried on from the patch's rim, where it takes `values` (#V×3, one row a
/// vertex of `skin`) of skin.rim_vertices, over kSeamBlendMm (blend_across_seam()). `far` itself
/// where `skin` has no rim.
DisplacementAt seam_field(const SkinSurfaces& skin, const Eigen::MatrixX3d& values,
                          DisplacementAt far);

/// A nodal field carried to the skin's vertices by the same shape functions that place the
/// micropolygons: f(v) = sum_a N_a(xi_v, eta_v, -1) f_a over the nodes of vertex v's element.
/// Vertices off the mesh (the range mesh, the end caps) get `off_mesh_value`, except where a
/// closure in the whole face reaches them: there the field of the tissue model's skin nodes
/// (closure::skin_scalar()), into which the patch's own goes over within kSeamBlendInsideMm of
/// its rim, so that a map of the whole face has no edge at the patch's rim.
/// @param skin     displaced_skin() of `mesh`
/// @param nodal    #N values, one per mesh node (any unit; the result has the same)
/// @return         #V values
/// Throws InvalidInput if `nodal` has the wrong size or a non-finite value.
Eigen::VectorXd nodal_field_on_skin(const SkinSurfaces& skin, const fem::Mesh& mesh,
                                    const Eigen::VectorXd& nodal, double off_mesh_value = 0.0);

}  // namespace caps::render

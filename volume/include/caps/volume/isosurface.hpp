#pragma once
/// @brief Isosurfaces of scalar volumes (marching cubes, flying-edges scheme), Taubin smoothing,
/// decimation and mesh statistics (area, enclosed volume, closed-manifold check).
///
/// Every mesh is a caps::TriMesh in patient LPS millimetres, counter-clockwise seen from outside.

#include "caps/core/mesh.hpp"
#include "caps/volume/volume.hpp"

namespace caps {

/// Marching-cubes isosurface of a volume, sampled at the voxel centres.
///
/// Each grid edge whose end values straddle `iso` gives exactly one vertex, placed by linear
/// interpolation along the edge; vertices are shared between cubes. Ambiguous cube faces are
/// resolved by one fixed rule (values > iso on opposite face corners stay separated), so
/// neighbouring cubes always agree and the mesh is edge-manifold and crack-free. Where the
/// surface does not touch the volume border it is closed; where it does, it stays open there
/// (pad the volume with one layer of values < iso to cap it). Runs in parallel (TBB); the output
/// is identical for any number of threads.
/// @param field  scalar volume (geometry: spacing, origin and direction are honoured); NaN
///               voxels count as below iso
/// @param iso    the level, in the units of the field (e.g. Hounsfield units); must be finite
/// @return       V #V×3 (LPS, mm), F #F×3 with normals pointing from values > iso (inside)
///               towards values < iso (outside), also for left-handed direction matrices.
///               Empty if the level is not crossed or a dimension is below 2.
TriMesh extract_isosurface(const Volume& field, float iso);

/// Taubin lambda/mu smoothing with uniform (umbrella) weights (Taubin 1995, "A signal processing
/// approach to fair surface design", SIGGRAPH, sec. 4): a shrinking step by `lambda` followed by an
/// inflating step by `mu`, repeated `iterations` times. Smooths noise without the shrinkage of
/// plain Laplacian smoothing. Runs in parallel; result independent of the thread count.
/// @param mesh        V #V×3 (any frame; positions are updated in place), F #F×3
/// @param iterations  number of lambda/mu pairs, >= 0
/// @param lambda      shrink factor in (0, 1)
/// @param mu          inflate factor, negative with |mu| > lambda (pass-band 1/lambda + 1/mu > 0)
void smooth_taubin(TriMesh& mesh, int iterations = 10, double lambda = 0.5, double mu = -0.53);

/// Edge-collapse decimation (CGAL Surface_mesh_simplification, Garland-Heckbert plane quadrics,
/// with a bounded-normal-change guard against fold-overs). Collapses keep the topology, so a
/// closed manifold stays a closed manifold.
/// @param mesh             V #V×3 (LPS, mm), F #F×3; non-manifold input is repaired by
///                         duplicating the offending vertices
/// @param target_fraction  fraction of faces to keep, in (0, 1]
/// @return                 the decimated mesh, with unused vertices removed
TriMesh decimate(const TriMesh& mesh, double target_fraction);

/// Total surface area.
/// @param mesh  V #V×3 (mm), F #F×3
/// @return      area in mm^2
double mesh_area(const TriMesh& mesh);

/// Signed enclosed volume by the divergence theorem, sum over faces of v0·(v1×v2)/6. Positive
/// for a closed mesh whose normals point outwards; meaningless for an open mesh.
/// @param mesh  V #V×3 (mm), F #F×3
/// @return      volume in mm^3
double mesh_volume(const TriMesh& mesh);

/// True if the mesh has at least one face and every edge is shared by exactly two faces that
/// traverse it in opposite directions (closed, edge-manifold, consistently oriented). Vertex
/// manifoldness (a single fan around each vertex) is not checked. Faces with a repeated vertex
/// or an out-of-range index make it false.
bool is_closed_manifold(const TriMesh& mesh);

}  // namespace caps

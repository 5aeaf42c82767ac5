#pragma once
/// @brief Internal to the surface mesher: re-triangulates a region that stage 1 filled, with
/// interior points and its boundary kept edge for edge (CGAL's constrained Delaunay mesher
/// without edge refinement). CGAL stays in stage1_region.cpp.

#include <Eigen/Core>
#include <array>
#include <vector>

namespace caps::mesher::detail {

struct RegionTriangulation {
  std::vector<Eigen::Vector2d> new_points;    ///< interior points, ids P.size(), P.size() + 1, ...
  std::vector<std::array<int, 3>> triangles;  ///< counter-clockwise, ids into P then new_points
};

/// Meshes the region bounded by `boundary` (edges (a, b) into P, mm; the region is what they
/// enclose by nesting parity) with triangles whose edges are at most `size_mm` and whose corners
/// are at least `min_angle_deg` (<= 20.7) where no boundary edge is in the way. Boundary edges
/// are never split and boundary points never move. Returns no triangles if the region cannot be
/// meshed (coincident points, crossing edges, a new point on the boundary).
RegionTriangulation triangulate_region(const std::vector<Eigen::Vector2d>& P,
                                       const std::vector<std::array<int, 2>>& boundary,
                                       double size_mm, double min_angle_deg);

}  // namespace caps::mesher::detail

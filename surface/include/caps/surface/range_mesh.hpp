#pragma once
/// @brief The polyhedral reconstruction of a range image (CAPS 1992, section 5): a vertex at every
/// sample, one quad per four neighbouring samples, split into two triangles.

#include <cstdint>

#include "caps/core/mesh.hpp"
#include "caps/volume/cylindrical_map.hpp"

namespace caps {

enum class RangeSurface { Skin, Bone };

struct RangeMeshOptions {
  /// Close the two open ends (the rows z_first and z_last) with a fan of triangles to a vertex
  /// on the axis, so the mesh is a closed manifold and a ray from above or below meets it.
  bool close_poles = true;
};

/// The range surface r(theta, z) of the maps as a triangle mesh (LPS mm, normals outward).
/// Vertex v = k * n_theta + j is sample (j, k); with close_poles the last two vertices are the
/// bottom and top pole. Quad (j, k)-(j+1, k)-(j+1, k+1)-(j, k+1), with j + 1 taken modulo
/// n_theta (the seam is closed), is split along the (j, k)-(j+1, k+1) diagonal into faces
/// 2q and 2q + 1, q = k * n_theta + j; pole fans follow, n_theta faces each.
/// @return #V = n_theta n_z (+2), #F = 2 n_theta (n_z - 1) (+ 2 n_theta)
TriMesh range_mesh(const CylindricalMaps& maps, RangeSurface which = RangeSurface::Skin,
                   const RangeMeshOptions& options = {});

/// The grid cell (j, k) whose quad holds face `f` of range_mesh(), or (-1, -1) for a pole face.
Eigen::Vector2i range_mesh_cell(const CylinderGrid& grid, Eigen::Index f);

}  // namespace caps

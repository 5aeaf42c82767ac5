#pragma once
/// @brief Quadratic tetrahedra (Tet10) from a linear tetrahedral mesh (4-node tets, e.g. the
/// whole-face model from a 3-D mesh generator): one mid-edge node per edge, shared by the
/// tetrahedra around it. Units as given (mm, LPS for caps meshes).

#include <Eigen/Core>
#include <vector>

#include "caps/fem/mesh.hpp"

namespace caps::fem {

/// The Tet10 mesh of a linear tetrahedral mesh.
struct QuadraticTetMesh {
  /// #V+#E × 3: the input corner nodes with their ids unchanged (unused ones kept), then one
  /// node per edge at the edge's midpoint (straight edges: the Tet10 is the linear tet's
  /// geometry, the boundary is not curved), edge k at id #V + k.
  Eigen::MatrixX3d nodes;
  /// One Tet10 per input tet, in input order: corners 0-3 are the tet's, 4-9 its mid-edge nodes
  /// in mesh.hpp's order (edges 0-1, 1-2, 2-0, 0-3, 1-3, 2-3).
  std::vector<Element> elements;
  /// #E × 2: the corner ids of each edge (smaller first); row k is mid-edge node #V + k. Edges
  /// are numbered in order of first appearance (tet by tet, local edges in the order above), so
  /// the result depends only on the input.
  Eigen::MatrixX2i edges;
};

/// Linear tetrahedra -> Tet10 elements with shared mid-edge nodes (QuadraticTetMesh).
/// @param V       #V×3 corner positions (mm)
/// @param T       #T×4 corner ids per tet, each with (x1-x0) x (x2-x0) . (x3-x0) > 0 (mesh.hpp)
/// @param layers  #T layer (material region) ids, one per tet
/// @return        the nodes, the elements (Element::layer from `layers`) and the edge table
/// Throws InvalidInput naming the tet if an id is out of range or repeated, a coordinate is not
/// finite, or a tet is inverted or degenerate (6 x its signed volume <= 1e-10 x its longest edge
/// cubed); an inverted tet's message says to swap two of its corners.
QuadraticTetMesh quadratic_tetrahedra(const Eigen::MatrixX3d& V, const Eigen::MatrixX4i& T,
                                      const Eigen::VectorXi& layers);

/// The same with one layer id for every tet.
QuadraticTetMesh quadratic_tetrahedra(const Eigen::MatrixX3d& V, const Eigen::MatrixX4i& T,
                                      int layer = 0);

}  // namespace caps::fem

#pragma once
/// @brief Structured test meshes: a box of Hex20 or Wedge15 elements, optionally with a
/// rectangular slot closed by sutures. For tests, benchmarks and `caps fem box`.

#include <Eigen/Core>

#include "caps/fem/mesh.hpp"

namespace caps::fem {

struct BoxOptions {
  Eigen::Vector3d size_mm{40, 10, 10};
  Eigen::Vector3i cells{8, 2, 2};
  bool wedges = false;      ///< split every cell into two Wedge15 (triangles in x-y)
  bool fix_bottom = true;   ///< fix all nodes at z = 0 (except sutured ones, as in the paper)
  /// Cut a slot one cell wide through the middle x column (cells.x() must be odd), over the
  /// middle half of the y cells, through all z; suture its two faces node by node.
  bool slot = false;
  std::shared_ptr<const Material> material = default_skin();  ///< of the one layer (0)
};

/// Builds the box [0,size] with face 0 of every element at its low z. Throws InvalidInput on
/// bad sizes or cell counts.
Mesh make_box_mesh(const BoxOptions& options);

}  // namespace caps::fem

#pragma once
/// @brief The triangle mesh type shared by every module.

#include <Eigen/Core>

namespace caps {

/// A triangle mesh: V #V×3 vertex positions (LPS, mm), F #F×3 vertex indices, counter-clockwise
/// seen from outside so that normals point out of the solid.
struct TriMesh {
  Eigen::MatrixX3d V;
  Eigen::MatrixX3i F;
  Eigen::Index n_vertices() const { return V.rows(); }
  Eigen::Index n_faces() const { return F.rows(); }
};

}  // namespace caps

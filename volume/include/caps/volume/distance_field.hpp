#pragma once
/// @brief Narrow-band signed distance fields of closed surfaces (OpenVDB level sets, kept in the
/// .cpp): the exact distance (mm) from any point near the skin or the bone to that surface, for
/// nearest-surface distances and skin/bone contact.

#include <Eigen/Core>
#include <memory>

#include "caps/core/mesh.hpp"

namespace caps {

/// A signed distance field of a closed triangle mesh on a sparse grid: negative inside, positive
/// outside, |value| = distance to the nearest point of the surface (mm), within a band around it.
class SignedDistanceField {
 public:
  /// Builds the field of `mesh` (V LPS mm, F triangles; closed, outward-facing) on a grid of
  /// `voxel_mm` cubes, `exterior_mm` outside and `interior_mm` inside the surface (the band).
  /// Throws InvalidInput for an empty mesh or non-positive sizes.
  static SignedDistanceField from_mesh(const TriMesh& mesh, double voxel_mm, double exterior_mm,
                                       double interior_mm);

  /// The signed distance (mm) at an LPS point, trilinear between voxels; outside the band it is
  /// +exterior_mm (outside) or -interior_mm (inside).
  double operator()(const Eigen::Vector3d& p_lps) const;
  /// Its gradient (unit near the surface; zero outside the band), by central differences.
  Eigen::Vector3d gradient(const Eigen::Vector3d& p_lps) const;
  double voxel_mm() const;
  /// Active voxels of the sparse grid (its memory is about 4-8 bytes each).
  std::size_t n_active_voxels() const;

 private:
  struct Impl;
  std::shared_ptr<const Impl> impl_;  // shared: the field is immutable once built
};

}  // namespace caps

#pragma once
/// @brief A surface given implicitly by a level set phi (mm): what the deep tissue slides on
/// (Mesh::sliding_surface; the bone's signed distance field in the patient's model). The FE
/// core knows only this interface; the field behind it (OpenVDB, analytic) lives above it.

#include <Eigen/Core>

namespace caps::fem {

/// A level set phi(x) (mm; a signed distance: |grad phi| = 1) and its gradient, in the mesh's
/// frame (LPS mm). The solver evaluates it from one thread at a time (never concurrently), at
/// positions near the surface (within the displacements of the sliding nodes).
class ImplicitSurface {
 public:
  virtual ~ImplicitSurface();
  /// phi at x (mm).
  virtual double distance(const Eigen::Vector3d& x_mm) const = 0;
  /// grad phi at x (dimensionless; unit for a signed distance); must be finite and nonzero
  /// where a sliding node is.
  virtual Eigen::Vector3d gradient(const Eigen::Vector3d& x_mm) const = 0;
};

}  // namespace caps::fem

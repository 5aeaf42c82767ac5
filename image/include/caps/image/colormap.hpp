#pragma once
/// @brief Colour maps for scalar fields.

#include <Eigen/Core>

namespace caps {

/// Perceptually uniform colour map (viridis, 11 stops linearly interpolated): t in [0, 1]
/// (clamped) to RGB in [0, 1]; viridis(0) = (68, 1, 84)/255, viridis(1) = (253, 231, 37)/255.
Eigen::Vector3d viridis(double t);

}  // namespace caps

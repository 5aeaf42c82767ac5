#pragma once
/// @brief Binary morphology on voxel masks: exact Euclidean distance transforms, erosion and
/// dilation by a radius in mm, connected components and hole filling.
///
/// Distances are physical (they honour anisotropic spacing) and exact (Felzenszwalb and
/// Huttenlocher 2012, "Distance Transforms of Sampled Functions", Theory of Computing 8).

#include <cstdint>
#include <vector>

#include "caps/volume/volume.hpp"

namespace caps {

/// Squared distance (mm^2) from every voxel centre to the centre of the nearest voxel where
/// `sites` is set (0 on the sites; kFar where there are none). If `nearest` is given it receives,
/// for every voxel, the linear index of that nearest site (-1 where there are none).
std::vector<float> squared_distance_mm2(const Mask& sites, std::vector<std::int64_t>* nearest = nullptr);
inline constexpr float kFar = 1e20f;

/// Voxels of `m` farther than radius_mm from every voxel outside it.
Mask erode(const Mask& m, double radius_mm);
/// Voxels within radius_mm of a voxel of `m`.
Mask dilate(const Mask& m, double radius_mm);

/// Connected components (6-connectivity). Returns per-voxel labels (0 = background, 1.. = the
/// components, sorted by decreasing size) and fills `sizes` with each label's voxel count
/// (sizes[0] is unused).
std::vector<std::int32_t> label_components(const Mask& m, std::vector<std::int64_t>& sizes);

/// Sets every background voxel that is not connected (6-connectivity) to the grid border.
void fill_enclosed_3d(Mask& m);
/// The same, slice by slice in the planes normal to grid axis `axis` (0, 1 or 2), with
/// 4-connectivity: fills cavities that open to the outside only through a channel across those
/// planes (for axial slices: the airway, nostrils and mouth).
void fill_enclosed_slices(Mask& m, int axis);

}  // namespace caps

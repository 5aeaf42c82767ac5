#pragma once
/// @brief Metal in a CT (dental fillings, crowns, implants): found, its streak artefacts removed
/// from the slices through it, and where the skin cannot be measured there, marked.
///
/// A CT reconstructs each axial slice on its own: metal in a slice starves the detector along
/// the rays through it and hardens the beam, which the reconstruction spreads back along those
/// rays as straight bright and dark streaks radiating from the metal across the whole slice,
/// strong enough (hundreds to thousands of HU) to raise the air outside the face above the skin
/// threshold (spikes) and to drop the soft tissue below it (holes). The slices without metal are
/// clean. docs/volume.md, "Metal", says how the rule below was chosen and what it does.

#include <Eigen/Core>
#include <cstddef>
#include <utility>
#include <vector>

#include "caps/volume/volume.hpp"

namespace caps {

struct MetalOptions {
  bool detect = true;            ///< look for metal (CT only)
  /// Voxels at or above this are metal: cortical bone reaches about 2000 HU and tooth enamel
  /// 2500-3000 HU at partial volume, dental alloys and amalgam 8000-30000 HU, stored clipped at
  /// 3071 HU (12 bits) or 32767 (16 bits).
  double threshold_hu = 3000.0;
  /// ... and a component is metal only when it reaches this somewhere: metal saturates a 12-bit
  /// CT (3071 HU) or lies far above it; bone and enamel stay below (Cranium's densest voxel,
  /// 2986 HU, is below both).
  double peak_hu = 3050.0;
  double min_mm3 = 4.0;          ///< a component smaller than this is noise, not metal
  /// A component larger than this (ml) or wider than max_extent_mm is not a dental or implant
  /// metal piece (the volume's scale is wrong); it is left alone.
  double max_ml = 30.0;
  double max_extent_mm = 100.0;
  /// The slices repaired are those holding metal and this far (mm, at least one slice) on
  /// either side: a helical reconstruction spreads the streaks over about one slice.
  double margin_mm = 1.5;
};

/// Where metal was found and which slices its streaks affect.
struct MetalRegion {
  bool checked = false;   ///< the volume was examined (a CT, detection on)
  bool found = false;
  VolumeGeometry geom;    ///< the volume's grid
  int slice_axis = 2;     ///< the grid axis across the axial slices (superior_axis())
  /// The ranges of slices [first, last] (along slice_axis) whose streaks were removed, sorted.
  std::vector<std::pair<int, int>> slabs;
  std::size_t voxels = 0;          ///< voxels at or above the threshold in the kept components
  int components = 0;
  double volume_mm3 = 0;
  double max_hu = 0;
  double threshold_hu = 0;
  Eigen::Vector3d centre_lps{0, 0, 0};  ///< the centroid of the largest piece
  double z_min_mm = 0, z_max_mm = 0;    ///< LPS S extent of the repaired slabs (mm)

  /// True when the LPS point lies in a repaired slab (within half a slice of its slices).
  bool in_slab(const Eigen::Vector3d& p_lps) const;
};

/// Finds metal in a CT: the connected components (6-connected) of voxels at or above
/// options.threshold_hu that reach options.peak_hu and whose volume lies between min_mm3 and max_ml and whose extent is at most
/// max_extent_mm. Non-CT volumes are not examined (checked = false).
MetalRegion detect_metal(const Volume& v, const MetalOptions& options = {});

/// The volume with each slab's slices replaced by the linear interpolation, voxel by voxel,
/// between the clean slices on either side of it (the one clean slice where the slab reaches the
/// grid's end): the metal and its streaks are gone, the anatomy between is bridged.
Volume repair_metal_slices(const Volume& v, const MetalRegion& metal);

}  // namespace caps

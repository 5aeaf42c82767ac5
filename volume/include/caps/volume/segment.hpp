#pragma once
/// @brief Skin and bone segmentation of a head CT or MR.
///
/// Runs on a working grid no finer than SegmentOptions::working_voxel_mm (block means of the
/// input), which keeps the topology work (components, hole filling, morphology) cheap; the
/// sub-voxel surfaces are found later on the full-resolution intensities, inside these masks.

#include <optional>
#include <string>
#include <vector>

#include "caps/core/reporter.hpp"
#include "caps/volume/metal.hpp"
#include "caps/volume/volume.hpp"

namespace caps {

struct SegmentOptions {
  /// Tissue/air threshold. Default: -400 HU for CT, Otsu's threshold for MR and unknown.
  std::optional<double> skin_threshold;
  /// Bone threshold. Default: +250 HU for CT; MR has none (see bone_mask and mr_scalp_mm).
  std::optional<double> bone_threshold;
  double working_voxel_mm = 1.5;  ///< segment on blocks averaging to about this size
  /// Opening radius that cuts the head loose from what touches it (table, head holder, wrapping):
  /// it removes attachments up to about twice this thick that meet the head broadly.
  double detach_radius_mm = 3.5;
  double detach_keep_ml = 15.0;   ///< pieces cut off but smaller than this are put back (ears)
  double bone_closing_mm = 1.5;   ///< closes gaps in thin facial bone
  double bone_keep_fraction = 0.02;  ///< keep bone components at least this part of the largest
  /// Optional bone mask or label volume (non-zero = bone), resampled by position. For MR.
  const Volume* bone_mask = nullptr;
  /// MR without a bone mask: bone is approximated as the skin envelope moved inward this far.
  double mr_scalp_mm = 6.0;
  /// Metal in a CT: the slices through it are repaired (repair_metal_slices()) before the
  /// working grid is made, so the masks hold neither the metal nor its streaks, whoever segments
  /// (build_volume_model() repairs the volume itself first, for the rays, and marks the cells).
  MetalOptions metal;
};

/// Result of segment_head(); masks are on the working grid.
struct Segmentation {
  Volume working;           ///< the intensities on the working grid
  Mask skin;                ///< the head's outer envelope, enclosed air filled
  Mask bone;                ///< bone (CT threshold, given mask, or the MR approximation)
  double skin_threshold = 0;
  double bone_threshold = 0;         ///< NaN when bone does not come from a threshold
  std::string skin_method;           ///< e.g. "threshold -400 HU"
  std::string bone_method;           ///< e.g. "threshold 250 HU", "mask FILE", "approximation"
  bool bone_is_approximate = false;  ///< true for MR without a bone mask
  double head_volume_ml = 0;
  double bone_volume_ml = 0;
  double detached_volume_ml = 0;     ///< what was cut away (table, head holder, wrapping)
  int detached_pieces = 0;
  std::vector<std::string> notes;
  MetalRegion metal;                 ///< the metal segment_head() found and repaired
};

/// Segments skin and bone. Throws InvalidInput when no head is found (nothing above the skin
/// threshold, or the largest object is smaller than a head) or options are out of range.
Segmentation segment_head(const Volume& v, const SegmentOptions& options = {},
                          Reporter* reporter = nullptr);

/// Otsu's threshold of the volume's intensities (256-bin histogram between min and max).
double otsu_threshold(const Volume& v);

/// The grid axis (0, 1, 2) most nearly parallel to LPS z (superior).
int superior_axis(const VolumeGeometry& g);

}  // namespace caps

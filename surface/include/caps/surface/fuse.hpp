#pragma once
/// @brief A model fused from a CT model and a registered surface scan of the same patient
/// (`caps model fuse`): the skin's colour from the scan, its depth structure (bone, thickness,
/// tissue layers) from the CT, and optionally the skin surface from the scan where it covers.

#include <Eigen/Core>
#include <cstddef>

#include "caps/core/reporter.hpp"
#include "caps/surface/scan_io.hpp"
#include "caps/volume/model_dir.hpp"

namespace caps {

struct FuseOptions {
  /// Take r_skin from the scan where it covers (else the CT's skin, the scan's colour only).
  bool scan_skin = false;
  /// A scan point further than this from the CT's skin along the ray is not the same skin
  /// (hair, a cap, a changed expression): neither its colour nor its radius is used there, mm.
  double max_gap_mm = 4.0;
};

/// A fused model: `ct`'s maps, meshes and layers, with the scan's colour where it covers.
struct FusedModel : ModelContent {
  std::size_t colored_cells = 0;   ///< grid cells coloured from the scan
  std::size_t gap_cells = 0;       ///< cells the scan covers further than max_gap_mm off the skin
  std::size_t skin_cells = 0;      ///< cells whose r_skin came from the scan (scan_skin)
  double median_gap_mm = 0;        ///< median |r_scan - r_ct| over the coloured cells
};

/// Fuses a scan into a CT model. Rays from the model's axis through every grid cell meet the
/// registered scan (its outermost crossing, as `caps model from-scan` measures a scan); where
/// they do within max_gap_mm of the CT's r_skin the cell takes the scan's colour (texture or
/// vertex colours, bilinear), and with scan_skin its r_skin: the radial thickness changes by the
/// same amount, the normal thickness and the layers in proportion, the bone stays the CT's.
/// Cells the scan does not cover keep the CT's colour (grey if it has none).
/// @param ct             the CT model (maps on its axis and grid, skin and bone meshes, colour)
/// @param scan           the scan as read, file units and frame, with its colour
/// @param scan_to_model  4×4, file units to LPS mm (register_scan()'s scan_to_model)
/// Throws InvalidInput for a scan without colour, a non-finite or singular transform, or a scan
/// that no ray from the axis meets.
FusedModel fuse_scan(const ModelContent& ct, const ScanMesh& scan,
                     const Eigen::Matrix4d& scan_to_model, const FuseOptions& options = {},
                     Reporter* reporter = nullptr);

}  // namespace caps

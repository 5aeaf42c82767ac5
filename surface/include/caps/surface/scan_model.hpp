#pragma once
/// @brief Patient models from surface scans (`caps model from-scan`): the scan is put in the
/// patient frame, the cylinder axis is fitted, r_skin is measured by rays cast from the axis
/// (outermost hit), the colour sampled through the texture, and the bone is the skin moved inward
/// by a constant thickness (CAPS 1992, section 4). The model directory is format 1.

#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>

#include "caps/surface/scan_io.hpp"
#include "caps/volume/model.hpp"

namespace caps {

/// A direction in the scan file's frame by name ("+x", "-x", "+y", "-y", "+z", "-z") or as three
/// numbers "X,Y,Z" (normalised). Throws InvalidInput naming `option` for anything else.
Eigen::Vector3d parse_axis_name(const std::string& name, const std::string& option);

/// The rotation taking scan-file coordinates to LPS given the file's up (patient superior) and
/// front (patient anterior, where the face looks) directions: rows are L = up x front, P =
/// -front, S = up. A proper rotation (determinant +1), so a scan is never mirrored.
/// Throws InvalidInput if up and front are not perpendicular unit vectors.
Eigen::Matrix3d scan_to_lps_rotation(const Eigen::Vector3d& up, const Eigen::Vector3d& front);

struct ScanModelOptions {
  double thickness_mm = 0;              ///< constant soft-tissue thickness, required, (0, 50]
  std::optional<double> mm_per_unit;    ///< --scale: file units to mm
  std::optional<double> head_height_mm; ///< --head-height-mm: scale so the scan is this tall
  Eigen::Vector3d up{0, 1, 0};          ///< file direction of patient superior
  Eigen::Vector3d front{0, 0, 1};       ///< file direction of patient anterior (the face)
  bool flip_faces = false;              ///< reverse every face (for inside-out files)
  MapOptions maps;                      ///< grid size and grazing limit
  std::optional<CylinderAxis> axis;     ///< overrides the fitted axis (LPS mm)
  /// Overrides the grid's z range (z0_mm and dz_mm of this grid are used; n_z from maps).
  std::optional<CylinderGrid> grid;
  double min_height_mm = 50, max_height_mm = 500;  ///< plausible scan heights
  std::string credit;                   ///< credit line for the pictures (e.g. the scan's licence)
};

/// A model built from a scan: skin is the scan in LPS mm, bone the range mesh of r_bone, color
/// the scan's colour sampled over the grid (empty if the scan has none).
struct ScanModel : ModelContent {
  double mm_per_unit = 1;     ///< the scale used
  double height_mm = 0;       ///< the scan's extent along superior
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  ///< file frame to LPS
  std::size_t inside_out_cells = 0;  ///< cells whose outermost hit faced the axis
  ScanMesh scan;              ///< the input (without texture pixels)
  ScanModelOptions options;
};

/// Validates a scan mesh: faces present, indices in range, finite vertices, every edge shared
/// by at most two faces. Throws InvalidInput naming the file and what to do.
void check_scan_mesh(const ScanMesh& scan);

/// Builds the model. Throws InvalidInput for an invalid mesh, absurd units (the message names
/// --scale / --head-height-mm), up/front that are not perpendicular, a thickness out of range,
/// an inside-out mesh, or a scan that no ray from the axis meets.
ScanModel build_scan_model(const ScanMesh& scan, const ScanModelOptions& options,
                           Reporter* reporter = nullptr);

/// Writes the model directory with write_model_directory() (the same writer as volume models);
/// model.json says source.kind = "scan" and thickness.kind = "constant".
void write_scan_model(const ScanModel& model, const std::filesystem::path& dir, bool force,
                      Reporter* reporter = nullptr);

}  // namespace caps

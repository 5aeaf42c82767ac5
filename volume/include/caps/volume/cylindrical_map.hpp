#pragma once
/// @brief Cylindrical range images of skin and bone (the Cyberware-style patient model) and the
/// soft-tissue thickness map, measured in a CT or MR volume.
///
/// Coordinates: an axis through the head (unit `direction`, superior), `front` perpendicular to it
/// (anterior). theta = 0 at the front, increasing towards the patient's left (right-handed about
/// the superior axis), in [-180, 180) degrees so the seam is at the back of the head. z is the
/// signed distance along the axis from `origin_lps` (mm); r the distance from the axis (mm).
/// Images are stored theta-fastest: value(j, k) at theta_j = theta0 + j dtheta, z_k = z0 + k dz.

#include <Eigen/Geometry>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "caps/core/reporter.hpp"
#include "caps/volume/segment.hpp"
#include "caps/volume/volume.hpp"

namespace caps {

/// The cylinder's axis and angular origin.
struct CylinderAxis {
  Eigen::Vector3d origin_lps{0, 0, 0};  ///< the point of the axis where z = 0
  Eigen::Vector3d direction{0, 0, 1};   ///< unit, towards superior
  Eigen::Vector3d front{0, -1, 0};      ///< unit, perpendicular to direction: theta = 0

  /// Unit vector towards theta = +90 degrees (the patient's left): direction x front.
  Eigen::Vector3d left() const { return direction.cross(front); }
  /// Unit ray direction at theta (radians).
  Eigen::Vector3d ray(double theta_rad) const;
  /// (theta [rad], z [mm], r [mm]) to LPS mm.
  Eigen::Vector3d to_lps(double theta_rad, double z_mm, double r_mm) const;
  /// LPS mm to (theta [rad] in [-pi, pi), z [mm], r [mm]).
  Eigen::Vector3d to_cylindrical(const Eigen::Vector3d& p) const;
};

/// The (theta, z) sampling grid.
struct CylinderGrid {
  int n_theta = 512;
  int n_z = 256;
  double theta0_deg = -180.0;
  double z0_mm = 0.0;
  double dz_mm = 1.0;
  double dtheta_deg() const { return 360.0 / n_theta; }
  double theta_deg(int j) const { return theta0_deg + j * dtheta_deg(); }
  double z_mm(int k) const { return z0_mm + k * dz_mm; }
  std::size_t size() const { return static_cast<std::size_t>(n_theta) * n_z; }
  std::size_t index(int j, int k) const { return static_cast<std::size_t>(k) * n_theta + j; }
};

/// Why a cell is not valid; a cell's flags are OR-ed, 0 means valid.
enum CellFlag : std::uint8_t {
  kNoSkin = 1,     ///< the ray never meets skin (above the vertex, below the neck cut)
  kNoBone = 2,     ///< no bone within MapOptions::bone_cap_mm under the skin (nose, lips, neck)
  kUndercut = 4,   ///< the ray crosses the skin more than once (ears, under the nose or chin)
  kGrazing = 8,    ///< the ray meets the skin at a grazing angle (near the vertex)
  kTruncated = 16, ///< the head touches the edge of the scanned volume along this ray
};

/// Short names of the flags, e.g. "no_bone|undercut".
std::string describe_flags(std::uint8_t flags);

/// A ray that re-enters the skin after an air gap of at least this length (mm) is kUndercut.
inline constexpr double kUndercutMinGapMm = 2.0;

struct MapOptions {
  int n_theta = 512;
  int n_z = 256;
  double bone_cap_mm = 40.0;     ///< no bone deeper than this under the skin -> kNoBone
  double grazing_deg = 70.0;     ///< ray-to-normal angle beyond which a cell is kGrazing
  /// The z range of the grid (mm along the axis); by default the head's extent.
  std::optional<double> z_min_mm, z_max_mm;
};

/// The maps. Images hold grid.size() values, theta fastest. Lengths in mm.
/// r_skin: outermost skin crossing (sub-voxel, half-maximum edge); r_bone: first bone crossing
/// inward from the skin; thickness = r_skin - r_bone (radial, what the extruder uses);
/// thickness_normal: distance from the skin point to the nearest bone (how clinicians measure).
/// Invalid cells are filled (see docs/model-format.md): r_skin and thickness by harmonic
/// interpolation from valid neighbours, so every value is finite; `flags` says which are measured.
struct CylindricalMaps {
  CylinderAxis axis;
  CylinderGrid grid;
  std::vector<float> r_skin, r_bone, thickness, thickness_normal;
  std::vector<std::uint8_t> flags;
  std::vector<std::uint8_t> measured_skin;  ///< 1 where r_skin was measured, 0 where filled
  std::vector<std::uint8_t> measured_bone;  ///< 1 where r_bone was measured, 0 where filled

  bool is_valid(int j, int k) const { return flags[grid.index(j, k)] == 0; }
  /// Sizes every image to grid.size(), all zero (nothing measured yet).
  void allocate();
};

/// The fill policy of every model (docs/model-format.md): values where known == 0 are replaced by
/// the solution of Laplace's equation with the known values as boundary conditions, periodic in
/// theta, no-flux at the z ends. `img` and `known` hold grid.size() values, theta fastest.
void harmonic_fill(std::vector<float>& img, const std::vector<std::uint8_t>& known,
                   const CylinderGrid& grid);

/// Sets kGrazing on measured cells (measured_skin) whose ray meets the range surface r_skin more
/// than `limit_deg` from its normal (slopes from central differences where both neighbours were
/// measured, one-sided otherwise). Used by volume and scan models alike.
void flag_grazing(CylindricalMaps& maps, double limit_deg);

/// Fits the axis to the segmented head: parallel to patient superior (LPS +z), through the
/// area-weighted centre of the head's axial cross-sections; front = anterior (LPS -y).
CylinderAxis fit_axis(const Segmentation& seg);

/// Casts one ray per grid cell from the axis outward and measures skin and bone.
/// `v` is the full-resolution volume `seg` was computed from.
CylindricalMaps cylindrical_maps(const Volume& v, const Segmentation& seg, const CylinderAxis& axis,
                                 const MapOptions& options = {}, Reporter* reporter = nullptr);

}  // namespace caps

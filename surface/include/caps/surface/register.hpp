#pragma once
/// @brief Registration of a surface scan onto a model's skin (`caps model register`): a rigid
/// motion (optionally with a uniform scale) found without hand-placed landmarks, and the distance
/// from every registered scan vertex to the skin.
///
/// Steps (docs/surface.md, "Registering a scan"):
/// 1. Units: the scan's millimetres per unit given, or the one of mm, cm and m that makes the
///    scan's size closest to the skin's.
/// 2. Coarse alignment: both surfaces sampled on a voxel grid, FPFH features (Rusu et al. 2009)
///    matched, and RANSAC over three-point correspondences (Open3D), scored by the fraction of
///    scan samples it brings within 1.5 voxels of the skin; with an orientation prior (the
///    file's up and front) only rotations near it are tried.
/// 3. Fine alignment: point-to-plane ICP (Chen and Medioni 1992) from a coarse to a fine
///    correspondence distance with a Tukey loss, so that scan parts the skin lacks (hair, a
///    cap, the chin outside the CT) are trimmed; with estimate_scale, scaled point-to-point
///    steps (Umeyama 1991) first.
/// 4. Residual: the signed distance from every registered scan vertex to the skin (positive
///    outside), its statistics, and the verdict whether the scan is of the same head.

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "caps/core/mesh.hpp"
#include "caps/core/reporter.hpp"

namespace caps {

struct RegistrationOptions {
  /// Millimetres per scan unit; unset: chosen among 1 (mm), 10 (cm) and 1000 (m) by size.
  std::optional<double> mm_per_unit;
  bool estimate_scale = false;  ///< refine a uniform scale (for scans in arbitrary units)
  /// A prior on the scan's orientation: the rotation taking scan-file directions to LPS (e.g.
  /// scan_to_lps_rotation() of the file's up and front). The coarse alignment then rejects
  /// rotations more than max_orientation_deg away from it. Unset: any orientation.
  std::optional<Eigen::Matrix3d> orientation;
  double max_orientation_deg = 45.0;  ///< (0, 180]
  double voxel_mm = 4.0;        ///< sampling of the coarse alignment, mm, [0.5, 20]
  double icp_final_mm = 2.0;    ///< the last ICP correspondence distance (trimming), mm
  double overlap_mm = 3.0;      ///< a scan vertex this close to the skin overlaps it, mm
  double max_rms_mm = 1.5;      ///< above this RMS over the overlap: another head, mm
  double max_median_mm = 1.0;   ///< above this median |distance| over the scan: another head, mm
  double min_overlap = 0.7;     ///< below this fraction of the scan overlapping: another head
  /// With estimate_scale: the estimate may move the scale from its start (given or guessed by
  /// size) by at most this factor either way; beyond it the scan is shrunk onto, or spread over,
  /// a part of the skin, which says another head or units far off (refused as another head).
  double max_scale_change = 1.5;
  int ransac_iterations = 200000;  ///< RANSAC trials of the coarse alignment
  int seed = 1;                 ///< random seed (the result is reproducible for one seed)
};

/// Statistics of the scan-to-skin distances.
struct ResidualStatistics {
  std::size_t vertices = 0;        ///< scan vertices measured
  std::size_t overlapping = 0;     ///< those within overlap_mm of the skin
  double overlap_fraction = 0;     ///< overlapping / vertices
  double rms_mm = 0;               ///< RMS of the distance over the overlapping vertices
  double rms_all_mm = 0;           ///< RMS over every vertex
  double median_mm = 0;            ///< median |distance| over every vertex
  double p90_mm = 0, p95_mm = 0, p99_mm = 0;  ///< percentiles of |distance| over every vertex
  double max_mm = 0;               ///< largest |distance|
  double mean_signed_mm = 0;       ///< mean signed distance over the overlap (+: scan outside)
};

struct ScanRegistration {
  /// p_model = T [p_scan; 1]: scan file units to the model's LPS mm, scale included.
  Eigen::Matrix4d scan_to_model = Eigen::Matrix4d::Identity();
  double scale = 1;              ///< millimetres per scan unit (the uniform scale in T)
  std::string scale_source;      ///< "given", "size (mm|cm|m)", or "estimated"
  Eigen::VectorXd distance_mm;   ///< #V signed distance of each registered vertex to the skin
  ResidualStatistics residual;
  bool same_head = false;        ///< rms, median and overlap within the options' limits
  std::string verdict;           ///< one sentence saying why
  double coarse_fitness = 0;     ///< fraction of scan samples near the skin after RANSAC
  double icp_fitness = 0;        ///< fraction of scan samples matched at the last ICP distance
  double seconds = 0;            ///< wall time of the registration
};

/// Registers `scan` onto `skin`. The library never refuses a poor fit: it says so in same_head
/// and verdict (the caller decides).
/// @param scan   V #V×3 in file units and frame, F #F×3 (partial coverage allowed)
/// @param skin   the model's skin, V LPS mm, F #F×3, outward faces
/// Throws InvalidInput for an empty mesh, options out of range, or a scan whose coarse alignment
/// finds no correspondence at all.
ScanRegistration register_scan(const TriMesh& scan, const TriMesh& skin,
                               const RegistrationOptions& options = {},
                               Reporter* reporter = nullptr);

/// Signed distances from points to a triangle mesh (nearest point on its faces, AABB tree):
/// positive on the side the faces' normals point to.
/// @param points  #P×3, the mesh's frame and units
/// @return        #P distances
Eigen::VectorXd signed_distance_to_mesh(const Eigen::MatrixX3d& points, const TriMesh& mesh);

/// The part of a mesh whose vertices are kept: the faces with all three corners kept, their
/// vertices renumbered in their first use (e.g. the face region of a skin, as a scan would cover).
/// @param keep_vertex  #V flags (non-zero: keep)
/// Throws InvalidInput if keep_vertex is not #V long.
TriMesh crop_mesh(const TriMesh& mesh, const std::vector<char>& keep_vertex);

/// The points moved by a 4×4 transform: T [p; 1] for every row.
Eigen::MatrixX3d transform_points(const Eigen::Matrix4d& T, const Eigen::MatrixX3d& points);

/// Residual statistics of signed distances (see ResidualStatistics).
ResidualStatistics residual_statistics(const Eigen::VectorXd& distance_mm, double overlap_mm);

}  // namespace caps

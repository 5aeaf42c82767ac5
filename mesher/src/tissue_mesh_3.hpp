#pragma once
/// @brief The one use of CGAL's 3-D mesh generator (Mesh_3) for the whole-face tissue model
/// (tissue_model.cpp): a label image meshed into linear tetrahedra. Internal to mesher.

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <vector>

#include "caps/core/reporter.hpp"

namespace caps::mesher::detail {

/// A label image in its own frame: voxel (i, j, k)'s centre at spacing_mm * (i, j, k) (mm),
/// i fastest; label 0 is outside, any other value one subdomain.
struct LabelImage {
  Eigen::Vector3i dims{0, 0, 0};
  Eigen::Vector3d spacing_mm{1, 1, 1};
  std::vector<std::uint8_t> labels;
};

/// Mesh_3 criteria; the sizes are functions of a point in the image's frame (mm).
struct Mesh3Criteria {
  std::function<double(const Eigen::Vector3d&)> facet_size_mm, facet_distance_mm, cell_size_mm;
  double facet_angle_deg = 25.0;
  double cell_radius_edge_ratio = 3.0;
  /// Initial surface points: up to this many, spread over the label boundary (every component
  /// gets some), so that no component is missed.
  int max_seeds = 4000;
  /// Sliver exudation after the refinement: at most this long (s; 0: none), aiming at a
  /// smallest dihedral angle of exude_sliver_bound_deg.
  double exude_seconds = 0.0;
  double exude_sliver_bound_deg = 10.0;
};

/// The tetrahedra of the subdomains (label != 0), in the image's frame.
struct Mesh3Output {
  Eigen::MatrixX3d nodes;           ///< mm, image frame
  Eigen::MatrixX4i tets;            ///< corners, positive orientation in the image frame
  Eigen::MatrixX3i boundary_faces;  ///< the facets of the subdomains' boundary
};

/// Meshes the label image (CGAL::Labeled_mesh_domain_3, make_mesh_3 refinement; no Lloyd, ODT,
/// perturbation or exudation). Throws InvalidInput for an empty image.
Mesh3Output mesh_label_image(const LabelImage& image, const Mesh3Criteria& criteria,
                             Reporter* reporter);

}  // namespace caps::mesher::detail

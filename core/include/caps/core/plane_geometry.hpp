#pragma once
/// @brief Small plane-geometry helpers shared by the modules that work in (theta, z) or on a
/// picture's plane: point in polygon, a polygon's area and centroid, angles wrapped to a
/// half-open turn.

#include <Eigen/Core>
#include <vector>

namespace caps {

/// Whether p lies inside the closed polygon `poly` (its vertices in order, the last joined to the
/// first), by the even-odd crossing rule. Affine-invariant: theta (deg) and z (mm) may be mixed.
/// A point exactly on the outline may fall either way; use point_in_or_on_polygon() to count it.
bool point_in_polygon(const std::vector<Eigen::Vector2d>& poly, const Eigen::Vector2d& p);

/// As point_in_polygon(), and true for a point on the outline to 1e-9 of the polygon's size
/// (at least 1e-9).
bool point_in_or_on_polygon(const std::vector<Eigen::Vector2d>& poly, const Eigen::Vector2d& p);

/// The signed area of the closed polygon `poly` (positive when its vertices run counterclockwise;
/// the shoelace formula).
double signed_area(const std::vector<Eigen::Vector2d>& poly);

/// The centroid of the closed polygon's area; where that area is 0 (the vertices on a line), the
/// vertices' mean. Affine-invariant, as point_in_polygon().
Eigen::Vector2d area_centroid(const std::vector<Eigen::Vector2d>& poly);

/// The angle (deg) wrapped into [-180, 180).
double wrap_degrees(double deg);

}  // namespace caps

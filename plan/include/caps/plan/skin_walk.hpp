#pragma once
/// @brief Walking on the skin: the skin's tangent plane at (theta, z) and walks along the cut's
/// segments as plans draw them (straight in (theta, z) between two points, which is how the
/// mesher and check_plan() lay a segment on the skin), with their length measured on the skin
/// and their turns measured in the skin's tangent plane. Templates are placed with these, so
/// lengths and angles drawn in a template's local mm are lengths and angles of the cut on the
/// skin, not in the plan frame linearised at the centre.

#include <Eigen/Core>

#include "caps/surface/patient_model.hpp"

namespace caps::plan {

/// The skin's tangent plane at a point: the parametric derivatives of skin_point() per degree
/// of theta and per mm of z (LPS mm / deg, LPS mm / mm, polar in theta with the radius's own
/// slopes), and the outward unit normal (LPS).
struct SkinTangent {
  Eigen::Vector3d d_theta{0, 0, 0};  ///< d skin_point / d theta, mm per deg
  Eigen::Vector3d d_z{0, 0, 0};      ///< d skin_point / d z, mm per mm
  Eigen::Vector3d normal{0, 0, 1};   ///< outward unit normal
  /// (dtheta deg, dz mm) whose skin displacement is the tangent vector v (LPS mm), least squares.
  Eigen::Vector2d to_theta_z(const Eigen::Vector3d& v) const;
};

/// The tangent plane of `model`'s skin at (theta deg, z mm). Throws InvalidInput when the skin
/// there is degenerate (on the axis) or the values are not finite.
SkinTangent skin_tangent(const PatientModel& model, double theta_deg, double z_mm);

/// A point on the skin with a tangent frame: (theta deg, z mm; theta not wrapped) and two unit
/// tangent vectors (LPS), ex and ey = normal x ex.
struct SkinFrame {
  Eigen::Vector2d theta_z{0, 0};
  Eigen::Vector3d ex{1, 0, 0}, ey{0, 1, 0};
};

/// The frame of the plan at (theta deg, z mm): ex at `orientation_deg` from superior towards
/// +theta, where 90 deg is horizontal (along the skin at constant z) and 0 is the skin's
/// superior direction perpendicular to it; ey = normal x ex (to the left of ex seen from outside).
SkinFrame skin_frame(const PatientModel& model, double theta_deg, double z_mm,
                     double orientation_deg);

/// Walks from `start` in the direction step_mm = (x, y) of its frame (mm along ex and ey) on the
/// line straight in (theta, z) that leaves the skin point in that direction, until |step_mm| mm
/// of skin are walked (midpoint rule, steps of at most 0.2 mm). Returns the end point with the
/// frame turned so that step_mm's direction is the direction of arrival there: the next walk
/// from it turns by the template's angle between the two segments, on the skin. On a cylinder
/// this is the geodesic and the frame is parallel.
SkinFrame walk_on_skin(const PatientModel& model, const SkinFrame& start,
                       const Eigen::Vector2d& step_mm);

/// The inverse of walk_on_skin(): the step_mm (mm along `start`'s ex and ey) whose walk from
/// `start` ends at `to` (theta deg, z mm; theta taken the short way round): the direction in
/// which the line straight in (theta, z) to `to` leaves the start, and that segment's length on
/// the skin (segment_length_on_skin()). Zero when `to` is the start.
Eigen::Vector2d step_on_skin(const PatientModel& model, const SkinFrame& start,
                             const Eigen::Vector2d& to);

/// The skin length (mm) of the segment from a to b (theta deg, z mm; b's theta unwrapped next
/// to a's) drawn straight in (theta, z), as plans draw it: the 3-D polyline through skin_point()
/// in steps of at most about 0.1 mm.
double segment_length_on_skin(const PatientModel& model, const Eigen::Vector2d& a,
                              const Eigen::Vector2d& b);

/// The point u (theta deg, z mm) whose segments from a and from b (drawn straight in (theta,
/// z)) are da and db mm long on the skin, found by Newton's method from `guess` (which picks
/// the side of a-b). Returns false (u untouched) when it does not converge to 1e-4 mm in 30
/// iterations, e.g. when da + db is shorter than the skin between a and b.
bool point_at_skin_distances(const PatientModel& model, const Eigen::Vector2d& a, double da,
                             const Eigen::Vector2d& b, double db, const Eigen::Vector2d& guess,
                             Eigen::Vector2d& u);

}  // namespace caps::plan

#include "caps/surface/chart.hpp"

#include <cmath>

#include "caps/core/error.hpp"

namespace caps {

Eigen::Vector3d mesh_normal_near(const TriMesh& skin, const Eigen::Vector3d& point,
                                 double radius_mm) {
  if (!(radius_mm > 0)) throw InvalidInput(cat("normal radius ", radius_mm, " mm: must be > 0"));
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  int faces = 0;
  for (Eigen::Index f = 0; f < skin.n_faces(); ++f) {
    const Eigen::Vector3d a = skin.V.row(skin.F(f, 0)).transpose();
    const Eigen::Vector3d b = skin.V.row(skin.F(f, 1)).transpose();
    const Eigen::Vector3d c = skin.V.row(skin.F(f, 2)).transpose();
    if (((a + b + c) / 3 - point).norm() > radius_mm) continue;
    sum += (b - a).cross(c - a);  // twice the area along the normal (counter-clockwise: outward)
    ++faces;
  }
  if (faces == 0)
    throw InvalidInput(cat("no skin surface lies within ", radius_mm, " mm of (", point.x(), ", ",
                           point.y(), ", ", point.z(), ") LPS mm"));
  if (!(sum.norm() > 1e-9))
    throw InvalidInput(cat("the skin's normal near (", point.x(), ", ", point.y(), ", ",
                           point.z(), ") LPS mm is undefined (its faces point every way)"));
  return sum.normalized();
}

ChartFrame chart_frame(const Eigen::Vector3d& point, const Eigen::Vector3d& normal,
                       const Eigen::Vector3d& up, const Eigen::Vector3d& fallback_up,
                       double radius_mm) {
  if (!(radius_mm > 0 && radius_mm <= 1000))
    throw InvalidInput(cat("chart radius ", radius_mm, " mm: give a distance in (0, 1000] mm"));
  if (!(normal.norm() > 1e-12)) throw InvalidInput("chart: the skin's normal is zero");
  ChartFrame c;
  c.point = point;
  c.normal = normal.normalized();
  c.radius_mm = radius_mm;
  // The axis: `up` without its component along the normal; where the normal lies within 30 deg
  // of up (the vertex), the fallback keeps the chart's z well defined.
  Eigen::Vector3d d = up - up.dot(c.normal) * c.normal;
  if (d.norm() < 0.5 * up.norm()) d = fallback_up - fallback_up.dot(c.normal) * c.normal;
  if (!(d.norm() > 1e-9)) throw InvalidInput("chart: no axis direction perpendicular to the normal");
  c.axis.direction = d.normalized();
  c.axis.front = c.normal;
  c.axis.origin_lps = point - radius_mm * c.normal;
  return c;
}

ChartFrame chart_frame(const PatientModel& model, const TriMesh& skin, double theta_deg,
                       double z_mm, double radius_mm, double normal_radius_mm) {
  const Eigen::Vector3d p = model.skin_point(theta_deg, z_mm);
  Eigen::Vector3d n = mesh_normal_near(skin, p, normal_radius_mm);
  // Outward: away from the model's axis, as the range image's own normal points.
  if (n.dot(model.skin_normal(theta_deg, z_mm)) < 0) n = -n;
  return chart_frame(p, n, model.axis().direction, model.axis().front, radius_mm);
}

}  // namespace caps

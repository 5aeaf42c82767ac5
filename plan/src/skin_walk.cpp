#include "caps/plan/skin_walk.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"

namespace caps::plan {

Eigen::Vector2d SkinTangent::to_theta_z(const Eigen::Vector3d& v) const {
  Eigen::Matrix<double, 3, 2> J;
  J << d_theta, d_z;
  return (J.transpose() * J).ldlt().solve(J.transpose() * v);
}

SkinTangent skin_tangent(const PatientModel& model, double theta_deg, double z_mm) {
  if (!std::isfinite(theta_deg) || !std::isfinite(z_mm))
    throw InvalidInput(cat("skin point (theta ", theta_deg, " deg, z ", z_mm,
                           " mm) must be finite numbers"));
  // Polar in theta (the radial and tangential unit vectors exactly), the radius's slopes from
  // central differences over less than a grid cell (the bilinear map's own slopes).
  const double ht = 0.25, hz = 0.25;
  const double r = model.r_skin(theta_deg, z_mm);
  const double r_t = (model.r_skin(theta_deg + ht, z_mm) - model.r_skin(theta_deg - ht, z_mm)) / (2 * ht);
  const double r_z = (model.r_skin(theta_deg, z_mm + hz) - model.r_skin(theta_deg, z_mm - hz)) / (2 * hz);
  const Eigen::Vector3d o = model.to_lps(theta_deg, z_mm, 0.0);
  const Eigen::Vector3d e_r = model.to_lps(theta_deg, z_mm, 1.0) - o;
  const Eigen::Vector3d e_t = model.to_lps(theta_deg + 90.0, z_mm, 1.0) - o;
  const Eigen::Vector3d e_z = model.to_lps(theta_deg, z_mm + 1.0, 0.0) - o;
  SkinTangent t;
  t.d_theta = r_t * e_r + deg_to_rad(1.0) * r * e_t;
  t.d_z = r_z * e_r + e_z;
  const Eigen::Vector3d n = t.d_theta.cross(t.d_z);
  if (!(n.norm() > 1e-9) || !n.allFinite())
    throw InvalidInput(cat("the skin at theta ", theta_deg, " deg, z ", z_mm,
                           " mm is degenerate (on the cylinder axis); pick another centre"));
  t.normal = n.normalized();
  return t;
}

SkinFrame skin_frame(const PatientModel& model, double theta_deg, double z_mm,
                     double orientation_deg) {
  const SkinTangent t = skin_tangent(model, theta_deg, z_mm);
  // Horizontal (constant z) towards +theta, and superior perpendicular to it on the skin;
  // (theta, z) is right-handed seen from outside.
  const Eigen::Vector3d right = t.d_theta.normalized();
  const Eigen::Vector3d up = t.normal.cross(right);
  const double phi = deg_to_rad(orientation_deg);
  SkinFrame f;
  f.theta_z = {theta_deg, z_mm};
  f.ex = std::cos(phi) * up + std::sin(phi) * right;
  f.ey = t.normal.cross(f.ex);
  return f;
}

SkinFrame walk_on_skin(const PatientModel& model, const SkinFrame& start,
                       const Eigen::Vector2d& step_mm) {
  const double length = step_mm.norm();
  SkinFrame f = start;
  if (!(length > 0)) return f;
  const double psi = std::atan2(step_mm.y(), step_mm.x());
  // The direction on the skin, and the line in (theta, z) that leaves in it.
  const Eigen::Vector3d leave = std::cos(psi) * f.ex + std::sin(psi) * f.ey;
  Eigen::Vector2d d = skin_tangent(model, f.theta_z[0], f.theta_z[1]).to_theta_z(leave);
  d.normalize();
  // March along it in steps of at most 0.2 mm of skin (midpoint rule for the skin's speed).
  const Eigen::Vector2d u0 = f.theta_z;
  double s = 0, walked = 0;
  auto speed = [&](double at) {
    const Eigen::Vector2d u = u0 + at * d;
    const SkinTangent t = skin_tangent(model, u[0], u[1]);
    return (d[0] * t.d_theta + d[1] * t.d_z).norm();
  };
  while (walked < length) {
    const double h = std::min(0.2, length - walked);
    const double ds = h / speed(s + 0.5 * h / speed(s));
    s += ds;
    walked += h;
  }
  f.theta_z = u0 + s * d;
  // The frame at the end: the template's direction along the direction of arrival.
  const SkinTangent t1 = skin_tangent(model, f.theta_z[0], f.theta_z[1]);
  const Eigen::Vector3d a = (d[0] * t1.d_theta + d[1] * t1.d_z).normalized();
  const Eigen::Vector3d b = t1.normal.cross(a);
  f.ex = std::cos(psi) * a - std::sin(psi) * b;
  f.ey = t1.normal.cross(f.ex);
  return f;
}

Eigen::Vector2d step_on_skin(const PatientModel& model, const SkinFrame& start,
                             const Eigen::Vector2d& to) {
  const Eigen::Vector2d u0 = start.theta_z;
  const Eigen::Vector2d d(std::remainder(to[0] - u0[0], 360.0), to[1] - u0[1]);
  const SkinTangent t = skin_tangent(model, u0[0], u0[1]);
  const Eigen::Vector3d v = t.d_theta * d[0] + t.d_z * d[1];
  if (v.norm() < 1e-12) return Eigen::Vector2d::Zero();
  const double length = segment_length_on_skin(model, u0, u0 + d);
  const Eigen::Vector3d u = v.normalized();
  return length * Eigen::Vector2d(u.dot(start.ex), u.dot(start.ey)).normalized();
}

double segment_length_on_skin(const PatientModel& model, const Eigen::Vector2d& a,
                              const Eigen::Vector2d& b_in) {
  Eigen::Vector2d b = b_in;
  b[0] = a[0] + std::remainder(b[0] - a[0], 360.0);
  Eigen::Vector3d last = model.skin_point(a[0], a[1]);
  const double chord = (model.skin_point(b[0], b[1]) - last).norm();
  const int n = std::clamp(static_cast<int>(std::ceil(chord / 0.1)), 16, 4000);
  double len = 0;
  for (int s = 1; s <= n; ++s) {
    const Eigen::Vector2d t = a + (b - a) * (static_cast<double>(s) / n);
    const Eigen::Vector3d x = model.skin_point(t[0], t[1]);
    len += (x - last).norm();
    last = x;
  }
  return len;
}

bool point_at_skin_distances(const PatientModel& model, const Eigen::Vector2d& a, double da,
                             const Eigen::Vector2d& b, double db, const Eigen::Vector2d& guess,
                             Eigen::Vector2d& u) {
  Eigen::Vector2d x = guess;
  auto residual = [&](const Eigen::Vector2d& p) {
    return Eigen::Vector2d(segment_length_on_skin(model, a, p) - da,
                           segment_length_on_skin(model, b, p) - db);
  };
  for (int it = 0; it < 30; ++it) {
    const Eigen::Vector2d r = residual(x);
    if (!r.allFinite()) return false;
    if (r.norm() < 1e-4) {
      u = x;
      return true;
    }
    Eigen::Matrix2d J;
    const double h = 1e-3;
    for (int k = 0; k < 2; ++k) {
      Eigen::Vector2d e = Eigen::Vector2d::Zero();
      e[k] = h;
      J.col(k) = (residual(x + e) - residual(x - e)) / (2 * h);
    }
    if (!(std::abs(J.determinant()) > 1e-12)) return false;
    Eigen::Vector2d step = J.partialPivLu().solve(r);
    // Steps of at most 2 mm of skin (about 2 / r rad of theta).
    const double s = step.norm();
    if (s > 2.0) step *= 2.0 / s;
    x -= step;
  }
  return false;
}

}  // namespace caps::plan

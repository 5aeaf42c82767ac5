#include "caps/surface/camera.hpp"

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"

#include <Eigen/Geometry>

#include <cmath>

namespace caps {

namespace {
constexpr int kMaxImagePx = 16384;
}  // namespace

Camera Camera::look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                       const Eigen::Vector3d& up, double fov_y_deg, int width_px, int height_px) {
  const Eigen::Vector3d view = target - eye;
  if (!(view.norm() > 1e-9))
    throw InvalidInput(cat("camera: the eye (", eye.transpose(), ") and the target coincide"));
  Camera c;
  c.projection = Projection::Perspective;
  c.target = target;
  c.forward = view / view.norm();
  c.up = up;
  c.distance_mm = view.norm();
  c.fov_y_deg = fov_y_deg;
  c.width_px = width_px;
  c.height_px = height_px;
  c.validate();
  return c;
}

void Camera::validate() const {
  if (!target.allFinite())
    throw InvalidInput(cat("camera: target (", target.transpose(), ") must be finite"));
  if (!forward.allFinite() || !(forward.norm() > 1e-12))
    throw InvalidInput(cat("camera: forward (", forward.transpose(), ") must be a direction"));
  const Eigen::Vector3d f = forward.normalized();
  if (!up.allFinite() || !((up - up.dot(f) * f).norm() > 1e-9 * up.norm()) || up.norm() == 0)
    throw InvalidInput(cat("camera: up (", up.transpose(), ") is zero or parallel to forward (",
                           forward.transpose(), ")"));
  if (!(distance_mm > 0) || !std::isfinite(distance_mm))
    throw InvalidInput(cat("camera: distance_mm ", distance_mm, " must be positive"));
  if (width_px < 1 || height_px < 1 || width_px > kMaxImagePx || height_px > kMaxImagePx)
    throw InvalidInput(
        cat("camera: image size ", width_px, "x", height_px, " pixels out of 1..", kMaxImagePx));
  if (projection == Projection::Orthographic && !(width_mm > 0 && std::isfinite(width_mm)))
    throw InvalidInput(cat("camera: orthographic width_mm ", width_mm, " must be positive"));
  if (projection == Projection::Perspective && !(fov_y_deg > 0 && fov_y_deg < 180))
    throw InvalidInput(cat("camera: perspective fov_y_deg ", fov_y_deg, " must be in (0, 180)"));
}

Eigen::Vector3d Camera::eye() const { return target - distance_mm * forward.normalized(); }

CameraFrame Camera::frame() const {
  CameraFrame f;
  f.forward = forward.normalized();
  f.up = (up - up.dot(f.forward) * f.forward).normalized();
  f.right = f.forward.cross(f.up);
  return f;
}

double Camera::pixel_scale() const {
  if (projection == Projection::Orthographic) return width_mm / width_px;
  return 0.5 * height_px / std::tan(0.5 * deg_to_rad(fov_y_deg));
}

// Orthographic: one pixel is pixel_scale() mm; perspective: one pixel at unit depth is
// 1 / pixel_scale() (the focal length in pixels). The render's byte-exact rays depend on the
// orthographic expressions keeping this form: (x − W/2) · mm-per-pixel.
Eigen::Vector2d Camera::image_plane(double x, double y) const {
  const double s = pixel_scale();
  if (projection == Projection::Orthographic)
    return {(x - 0.5 * width_px) * s, (0.5 * height_px - y) * s};
  return {(x - 0.5 * width_px) / s, (0.5 * height_px - y) / s};
}

Ray Camera::ray(double x, double y) const {
  validate();
  const CameraFrame f = frame();
  const Eigen::Vector2d q = image_plane(x, y);
  if (projection == Projection::Orthographic)
    return {target + q.x() * f.right + q.y() * f.up - distance_mm * f.forward, f.forward};
  return {eye(), (f.forward + q.x() * f.right + q.y() * f.up).normalized()};
}

Eigen::Vector2d Camera::project(const Eigen::Vector3d& p) const {
  validate();
  const CameraFrame f = frame();
  const double s = pixel_scale();
  if (projection == Projection::Orthographic) {
    const Eigen::Vector3d q = p - target;
    return {q.dot(f.right) / s + 0.5 * width_px, 0.5 * height_px - q.dot(f.up) / s};
  }
  const Eigen::Vector3d q = p - eye();
  const double depth = q.dot(f.forward);
  if (!(depth > 0))
    throw InvalidInput(cat("camera: point (", p.transpose(), ") is not in front of the eye (",
                           eye().transpose(), "); depth ", depth, " mm"));
  return {0.5 * width_px + s * q.dot(f.right) / depth, 0.5 * height_px - s * q.dot(f.up) / depth};
}

double Camera::depth_mm(const Eigen::Vector3d& p) const {
  return (p - eye()).dot(forward.normalized());
}

}  // namespace caps

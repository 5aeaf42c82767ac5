#pragma once
/// @brief The one camera of caps: it turns a pixel into a ray (picking, the renderer's rays) and
/// an LPS point into a pixel (overlays, tests), orthographic or perspective (pinhole), with one
/// pixel convention in both directions: pixel (0, 0) is the top-left corner of the image, x grows
/// to the right, y downwards, and pixel (i, j) covers [i, i + 1) × [j, j + 1), so its centre is
/// (i + 0.5, j + 0.5).

#include <Eigen/Core>

namespace caps {

/// A ray, LPS mm. `direction` need not be unit length but must not be zero.
struct Ray {
  Eigen::Vector3d origin{0, 0, 0};
  Eigen::Vector3d direction{0, 0, 1};
};

enum class Projection {
  Orthographic,  ///< parallel rays along `forward`; `width_mm` of the scene across the image
  Perspective,   ///< rays from the eye; `fov_y_deg` from the top of the image to its bottom
};

/// The orthonormal frame of a camera (LPS, unit vectors): `right` along the image's x, `up`
/// against its y, `forward` into the scene; right = forward × up, so (right, up, −forward) is
/// right-handed (the viewer looks along −z, as in OpenGL's eye space).
struct CameraFrame {
  Eigen::Vector3d right{1, 0, 0};
  Eigen::Vector3d up{0, 0, 1};
  Eigen::Vector3d forward{0, 1, 0};
};

/// A camera looking along `forward` at `target`, the scene point seen at the image's centre
/// (pixel (width_px / 2, height_px / 2)). The eye is `distance_mm` before the target: the centre
/// of projection of a perspective camera, the centre of the plane the rays start from of an
/// orthographic one. The default looks at the face (forward = +y, posterior) from 600 mm in
/// front, with the patient's superior (+z) up and their left (+x) on the image's right.
struct Camera {
  Projection projection = Projection::Orthographic;
  Eigen::Vector3d target{0, 0, 0};      ///< LPS mm, seen at the image's centre
  Eigen::Vector3d forward{0, 1, 0};     ///< viewing direction (normalised on use)
  Eigen::Vector3d up{0, 0, 1};          ///< towards the image's top (made orthogonal to forward)
  double distance_mm = 600;             ///< from the eye to the target along forward (> 0)
  double width_mm = 300;                ///< orthographic: the image's width in the scene
  double fov_y_deg = 30;                ///< perspective: vertical field of view, (0, 180)
  int width_px = 800, height_px = 800;  ///< image size in pixels

  /// A perspective camera at `eye` looking at `target` (LPS mm). Throws InvalidInput if they
  /// coincide.
  static Camera look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                        const Eigen::Vector3d& up, double fov_y_deg, int width_px, int height_px);

  /// Throws InvalidInput, naming the field, unless the camera is usable: finite target, a
  /// non-zero forward, up not parallel to it, distance_mm > 0, width_mm > 0 (orthographic),
  /// 0 < fov_y_deg < 180 (perspective), 1..16384 pixels each way.
  void validate() const;

  /// The eye: target − distance_mm · forward̂ (LPS mm).
  Eigen::Vector3d eye() const;
  /// The orthonormal frame (its up is the part of `up` orthogonal to forward, normalised).
  CameraFrame frame() const;
  /// Orthographic: the scene's size of one pixel (mm, width_mm / width_px). Perspective: the
  /// focal length in pixels, (height_px / 2) / tan(fov_y / 2).
  double pixel_scale() const;

  /// Pixel (x, y) (pixel units, fractional; centres at half-integers) on the image plane:
  /// orthographic, its offset from the target along right and up in mm; perspective, the slopes
  /// (right, up) of its ray per unit of depth along forward. Does not validate.
  Eigen::Vector2d image_plane(double x, double y) const;

  /// The ray through pixel (x, y): orthographic, from the eye's plane along forward̂;
  /// perspective, from the eye, unit direction. Throws InvalidInput for an invalid camera.
  Ray ray(double x, double y) const;

  /// The pixel (x, y) where `p` (LPS mm) appears; ray(project(p)) passes through p. Throws
  /// InvalidInput for an invalid camera or, perspective, for p not in front of the eye.
  Eigen::Vector2d project(const Eigen::Vector3d& p) const;

  /// The depth of `p` (LPS mm): its distance from the eye's plane along forward̂ (mm).
  double depth_mm(const Eigen::Vector3d& p) const;
};

}  // namespace caps

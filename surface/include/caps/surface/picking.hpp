#pragma once
/// @brief Picking on the skin (CAPS 1992, section 5, "Operating on the Surface"): a ray from the
/// camera through a pixel (Camera::ray, camera.hpp) meets the skin's polyhedral reconstruction;
/// the nearest plan point to a ray. Rays are tested against an AABB tree (CGAL), built once, not
/// against every polygon.

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "caps/core/mesh.hpp"
#include "caps/surface/camera.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/surface/range_mesh.hpp"

namespace caps {

/// One intersection of a ray with a triangle mesh.
struct MeshHit {
  double t = 0;              ///< ray parameter: point = origin + t * direction
  Eigen::Index face = -1;    ///< the triangle
  Eigen::Vector3d point{0, 0, 0};
};

/// Ray casting against a fixed triangle mesh through an AABB tree (built once, in the
/// constructor; queries are thread-safe). Triangles without area (collinear corners) are never
/// hit, as they are invisible in a rendered image.
class MeshRayCaster {
 public:
  /// @param mesh  V #V×3, F #F×3; copied. Throws InvalidInput if it has no faces.
  explicit MeshRayCaster(const TriMesh& mesh);
  ~MeshRayCaster();
  MeshRayCaster(MeshRayCaster&&) noexcept;
  MeshRayCaster& operator=(MeshRayCaster&&) noexcept;

  /// The first hit with t > 0, or nothing.
  std::optional<MeshHit> first_hit(const Ray& ray) const;
  /// Every hit with t > 0, nearest first (a ray through an edge may report both faces).
  std::vector<MeshHit> all_hits(const Ray& ray) const;
  const TriMesh& mesh() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The first hit of a ray on a mesh by testing every triangle (Moller-Trumbore); the reference
/// for tests. Slow: O(#F).
std::optional<MeshHit> first_hit_brute_force(const TriMesh& mesh, const Ray& ray);

/// A pick on the skin.
struct SkinHit {
  bool hit = false;                 ///< false: the ray misses the skin
  double distance_mm = 0;           ///< from the ray origin along the unit direction
  Eigen::Vector3d lps{0, 0, 0};     ///< the point on the skin's polyhedral reconstruction
  double theta_deg = 0, z_mm = 0;   ///< its cylindrical coordinates
  std::uint8_t flags = 0;           ///< validity flags there (PatientModel::flags_at)
  bool on_pole_cap = false;         ///< the ray met the cap closing the top or bottom row
};

/// A plan point picked by a ray.
struct PointPick {
  int index = -1;                   ///< into the points given; -1: none within the tolerance
  double distance_to_ray_mm = 0;    ///< perpendicular distance from the ray
  double along_ray_mm = 0;          ///< distance of its foot from the ray origin
};

/// The point nearest to the ray (perpendicular distance) among those in front of its origin and
/// within `tolerance_mm` of it; ties go to the one nearer the origin.
/// @param points  #P×3 LPS mm
PointPick pick_nearest_point(const Eigen::MatrixX3d& points, const Ray& ray, double tolerance_mm);

/// Picking on a patient model's skin: the range mesh of r_skin with closed poles, in an AABB tree.
class SkinPicker {
 public:
  /// Builds the tree for the model's skin; the model is copied (its maps are needed for flags).
  explicit SkinPicker(const PatientModel& model);

  /// The first hit of the ray on the skin, or hit = false.
  SkinHit pick(const Ray& ray) const;
  /// Like pick_nearest_point(), ignoring points hidden behind the skin (more than
  /// `tolerance_mm` beyond the ray's first skin hit).
  PointPick pick_point(const Eigen::MatrixX3d& points, const Ray& ray, double tolerance_mm) const;

  const TriMesh& mesh() const { return caster_.mesh(); }
  const PatientModel& model() const { return model_; }

 private:
  PatientModel model_;
  MeshRayCaster caster_;
};

}  // namespace caps

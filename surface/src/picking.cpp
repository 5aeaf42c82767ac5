#include "caps/surface/picking.hpp"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "caps/core/error.hpp"

namespace caps {
namespace {

// Exact predicates: a ray through an edge shared by two triangles meets at least one of them.
// With inexact predicates (Simple_cartesian) both orientation tests can round the wrong way, and
// a ray from the axis through a vertical edge of a cylindrical range image met no face at all.
using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Vector = Kernel::Vector_3;
using Triangle = Kernel::Triangle_3;
using CgalRay = Kernel::Ray_3;
using Iterator = std::vector<Triangle>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<Kernel, Iterator>;
using Traits = CGAL::AABB_traits<Kernel, Primitive>;
using Tree = CGAL::AABB_tree<Traits>;

Point to_point(const Eigen::Vector3d& p) { return {p[0], p[1], p[2]}; }

void check_ray(const Ray& ray) {
  if (!ray.origin.allFinite() || !ray.direction.allFinite() || ray.direction.norm() == 0)
    throw InvalidInput(cat("ray origin (", ray.origin.transpose(), ") direction (",
                           ray.direction.transpose(), "): must be finite with a non-zero direction"));
}

}  // namespace

struct MeshRayCaster::Impl {
  TriMesh mesh;
  std::vector<Triangle> triangles;    // the mesh's triangles with an area
  std::vector<Eigen::Index> face_of;  // #triangles: their faces in `mesh`
  Tree tree;

  // The hit of a CGAL intersection result: the nearest point of a point or segment.
  template <typename Result>
  MeshHit to_hit(const Result& r, const Ray& ray) const {
    Eigen::Vector3d p;
    if (const Point* q = boost::get<Point>(&r.first)) {
      p = {q->x(), q->y(), q->z()};
    } else {
      const auto* s = boost::get<Kernel::Segment_3>(&r.first);
      const Eigen::Vector3d a(s->source().x(), s->source().y(), s->source().z());
      const Eigen::Vector3d b(s->target().x(), s->target().y(), s->target().z());
      p = (a - ray.origin).dot(ray.direction) <= (b - ray.origin).dot(ray.direction) ? a : b;
    }
    MeshHit h;
    h.point = p;
    h.t = (p - ray.origin).dot(ray.direction) / ray.direction.squaredNorm();
    h.face = face_of[static_cast<std::size_t>(r.second - triangles.begin())];
    return h;
  }
};

MeshRayCaster::MeshRayCaster(const TriMesh& mesh) : impl_(std::make_unique<Impl>()) {
  if (mesh.n_faces() == 0) throw InvalidInput("ray casting: the mesh has no faces");
  impl_->mesh = mesh;
  auto& tris = impl_->triangles;
  tris.reserve(mesh.n_faces());
  for (Eigen::Index f = 0; f < mesh.n_faces(); ++f) {
    for (int c = 0; c < 3; ++c)
      if (mesh.F(f, c) < 0 || mesh.F(f, c) >= mesh.n_vertices())
        throw InvalidInput(cat("ray casting: face ", f, " has vertex index ", mesh.F(f, c),
                               " outside 0..", mesh.n_vertices() - 1));
    const Triangle t(to_point(mesh.V.row(mesh.F(f, 0))), to_point(mesh.V.row(mesh.F(f, 1))),
                     to_point(mesh.V.row(mesh.F(f, 2))));
    // A triangle without area (e.g. a wound fill collapsed by the closure) shows nothing; a
    // renderer does not see it, so picking must not meet it either.
    if (t.is_degenerate()) continue;
    tris.push_back(t);
    impl_->face_of.push_back(f);
  }
  impl_->tree.insert(tris.cbegin(), tris.cend());
  impl_->tree.build();
}

MeshRayCaster::~MeshRayCaster() = default;
MeshRayCaster::MeshRayCaster(MeshRayCaster&&) noexcept = default;
MeshRayCaster& MeshRayCaster::operator=(MeshRayCaster&&) noexcept = default;

const TriMesh& MeshRayCaster::mesh() const { return impl_->mesh; }

std::optional<MeshHit> MeshRayCaster::first_hit(const Ray& ray) const {
  check_ray(ray);
  if (impl_->triangles.empty()) return std::nullopt;
  const CgalRay r(to_point(ray.origin), Vector(ray.direction[0], ray.direction[1], ray.direction[2]));
  const auto result = impl_->tree.first_intersection(r);
  if (!result) return std::nullopt;
  MeshHit h = impl_->to_hit(*result, ray);
  if (!(h.t > 0)) {
    // The origin lies on the surface: take the next hit beyond it.
    for (const auto& hit : all_hits(ray))
      if (hit.t > 1e-9) return hit;
    return std::nullopt;
  }
  return h;
}

std::vector<MeshHit> MeshRayCaster::all_hits(const Ray& ray) const {
  check_ray(ray);
  if (impl_->triangles.empty()) return {};
  const CgalRay r(to_point(ray.origin), Vector(ray.direction[0], ray.direction[1], ray.direction[2]));
  using Result = Tree::Intersection_and_primitive_id<CgalRay>::Type;
  std::vector<Result> results;
  impl_->tree.all_intersections(r, std::back_inserter(results));
  std::vector<MeshHit> hits;
  hits.reserve(results.size());
  for (const auto& res : results) {
    MeshHit h = impl_->to_hit(res, ray);
    if (h.t > 0) hits.push_back(h);
  }
  std::sort(hits.begin(), hits.end(), [](const MeshHit& a, const MeshHit& b) { return a.t < b.t; });
  return hits;
}

std::optional<MeshHit> first_hit_brute_force(const TriMesh& mesh, const Ray& ray) {
  check_ray(ray);
  std::optional<MeshHit> best;
  const Eigen::Vector3d& o = ray.origin;
  const Eigen::Vector3d& d = ray.direction;
  // Moller & Trumbore (1997), "Fast, minimum storage ray-triangle intersection".
  for (Eigen::Index f = 0; f < mesh.n_faces(); ++f) {
    const Eigen::Vector3d a = mesh.V.row(mesh.F(f, 0)), b = mesh.V.row(mesh.F(f, 1)),
                          c = mesh.V.row(mesh.F(f, 2));
    const Eigen::Vector3d e1 = b - a, e2 = c - a, p = d.cross(e2);
    const double det = e1.dot(p);
    if (std::abs(det) < 1e-14 * e1.norm() * e2.norm() * d.norm()) continue;
    const Eigen::Vector3d s = o - a;
    const double u = s.dot(p) / det;
    if (u < 0 || u > 1) continue;
    const Eigen::Vector3d q = s.cross(e1);
    const double v = d.dot(q) / det;
    if (v < 0 || u + v > 1) continue;
    const double t = e2.dot(q) / det;
    if (t <= 0 || (best && t >= best->t)) continue;
    best = MeshHit{t, f, o + t * d};
  }
  return best;
}

PointPick pick_nearest_point(const Eigen::MatrixX3d& points, const Ray& ray, double tolerance_mm) {
  check_ray(ray);
  const Eigen::Vector3d d = ray.direction.normalized();
  PointPick best;
  double best_dist = std::numeric_limits<double>::max(), best_along = best_dist;
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Eigen::Vector3d q = points.row(i).transpose() - ray.origin;
    const double along = q.dot(d);
    if (along <= 0) continue;
    const double dist = (q - along * d).norm();
    if (dist > tolerance_mm) continue;
    if (dist < best_dist - 1e-9 || (dist <= best_dist + 1e-9 && along < best_along)) {
      best = {static_cast<int>(i), dist, along};
      best_dist = dist;
      best_along = along;
    }
  }
  return best;
}

SkinPicker::SkinPicker(const PatientModel& model)
    : model_(model), caster_(range_mesh(model.maps(), RangeSurface::Skin, {true})) {}

SkinHit SkinPicker::pick(const Ray& ray) const {
  SkinHit out;
  const auto h = caster_.first_hit(ray);
  if (!h) return out;
  out.hit = true;
  out.lps = h->point;
  out.distance_mm = h->t * ray.direction.norm();
  const CylindricalPoint c = model_.to_cylindrical(h->point);
  out.theta_deg = c.theta_deg;
  out.z_mm = c.z_mm;
  out.on_pole_cap = range_mesh_cell(model_.grid(), h->face)[0] < 0;
  out.flags = model_.flags_at(c.theta_deg, c.z_mm);
  return out;
}

PointPick SkinPicker::pick_point(const Eigen::MatrixX3d& points, const Ray& ray,
                                 double tolerance_mm) const {
  const SkinHit skin = pick(ray);
  if (!skin.hit) return pick_nearest_point(points, ray, tolerance_mm);
  const Eigen::Vector3d d = ray.direction.normalized();
  Eigen::MatrixX3d visible(points.rows(), 3);
  std::vector<int> index;
  for (Eigen::Index i = 0; i < points.rows(); ++i)
    if ((points.row(i).transpose() - ray.origin).dot(d) <= skin.distance_mm + tolerance_mm) {
      visible.row(static_cast<Eigen::Index>(index.size())) = points.row(i);
      index.push_back(static_cast<int>(i));
    }
  visible.conservativeResize(static_cast<Eigen::Index>(index.size()), 3);
  PointPick p = pick_nearest_point(visible, ray, tolerance_mm);
  if (p.index >= 0) p.index = index[p.index];
  return p;
}

}  // namespace caps

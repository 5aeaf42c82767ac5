#include "caps/volume/distance_field.hpp"

#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/MeshToVolume.h>

#include <mutex>
#include <vector>

#include "caps/core/error.hpp"

namespace caps {

struct SignedDistanceField::Impl {
  openvdb::FloatGrid::Ptr grid;
  double voxel = 1.0;
};

SignedDistanceField SignedDistanceField::from_mesh(const TriMesh& mesh, double voxel_mm,
                                                   double exterior_mm, double interior_mm) {
  if (mesh.n_faces() == 0 || mesh.n_vertices() == 0)
    throw InvalidInput("signed distance field: the mesh is empty");
  if (!(voxel_mm > 0) || !(exterior_mm > 0) || !(interior_mm > 0))
    throw InvalidInput(cat("signed distance field: voxel ", voxel_mm, " mm and band ", exterior_mm,
                           " / ", interior_mm, " mm must be positive"));
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
  std::vector<openvdb::Vec3s> points(static_cast<std::size_t>(mesh.n_vertices()));
  for (Eigen::Index i = 0; i < mesh.n_vertices(); ++i)
    points[i] = openvdb::Vec3s(static_cast<float>(mesh.V(i, 0)), static_cast<float>(mesh.V(i, 1)),
                               static_cast<float>(mesh.V(i, 2)));
  // World space is LPS mm (the conversion maps the points to index space itself).
  const auto xform = openvdb::math::Transform::createLinearTransform(voxel_mm);
  std::vector<openvdb::Vec3I> tris(static_cast<std::size_t>(mesh.n_faces()));
  for (Eigen::Index f = 0; f < mesh.n_faces(); ++f)
    tris[f] = openvdb::Vec3I(mesh.F(f, 0), mesh.F(f, 1), mesh.F(f, 2));
  auto impl = std::make_shared<Impl>();
  impl->voxel = voxel_mm;
  impl->grid = openvdb::tools::meshToSignedDistanceField<openvdb::FloatGrid>(
      *xform, points, tris, std::vector<openvdb::Vec4I>(),
      static_cast<float>(exterior_mm / voxel_mm), static_cast<float>(interior_mm / voxel_mm));
  SignedDistanceField f;
  f.impl_ = std::move(impl);
  return f;
}

double SignedDistanceField::operator()(const Eigen::Vector3d& p) const {
  const auto& grid = *impl_->grid;
  const openvdb::Vec3d q = grid.transform().worldToIndex(openvdb::Vec3d(p[0], p[1], p[2]));
  return openvdb::tools::BoxSampler::sample(grid.tree(), q);
}

Eigen::Vector3d SignedDistanceField::gradient(const Eigen::Vector3d& p) const {
  const double h = 0.5 * impl_->voxel;
  Eigen::Vector3d g;
  for (int a = 0; a < 3; ++a) {
    Eigen::Vector3d e = Eigen::Vector3d::Zero();
    e[a] = h;
    g[a] = ((*this)(p + e) - (*this)(p - e)) / (2 * h);
  }
  return g;
}

double SignedDistanceField::voxel_mm() const { return impl_->voxel; }

std::size_t SignedDistanceField::n_active_voxels() const {
  return static_cast<std::size_t>(impl_->grid->activeVoxelCount());
}

}  // namespace caps

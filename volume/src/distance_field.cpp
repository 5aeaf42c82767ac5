#include "caps/volume/distance_field.hpp"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/FastSweeping.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/MeshToVolume.h>
#include <openvdb/tools/Prune.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <mutex>
#include <vector>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/volume/morphology.hpp"

namespace caps {

namespace {

void initialize_vdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

}  // namespace

struct SignedDistanceField::Impl {
  openvdb::FloatGrid::Ptr grid;
  double voxel = 1.0;
  double exterior = 0, interior = 0;
};

SignedDistanceField SignedDistanceField::from_mesh(const TriMesh& mesh, double voxel_mm,
                                                   double exterior_mm, double interior_mm) {
  if (mesh.n_faces() == 0 || mesh.n_vertices() == 0)
    throw InvalidInput("signed distance field: the mesh is empty");
  if (!(voxel_mm > 0) || !(exterior_mm > 0) || !(interior_mm > 0))
    throw InvalidInput(cat("signed distance field: voxel ", voxel_mm, " mm and band ", exterior_mm,
                           " / ", interior_mm, " mm must be positive"));
  initialize_vdb();
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
  impl->exterior = exterior_mm;
  impl->interior = interior_mm;
  impl->grid = openvdb::tools::meshToSignedDistanceField<openvdb::FloatGrid>(
      *xform, points, tris, std::vector<openvdb::Vec4I>(),
      static_cast<float>(exterior_mm / voxel_mm), static_cast<float>(interior_mm / voxel_mm));
  impl->grid->setGridClass(openvdb::GRID_LEVEL_SET);
  SignedDistanceField f;
  f.impl_ = std::move(impl);
  return f;
}

SignedDistanceField SignedDistanceField::from_mask(const Mask& mask, double voxel_mm,
                                                   double exterior_mm, double interior_mm) {
  if (!(voxel_mm > 0) || !(exterior_mm > 0) || !(interior_mm > 0))
    throw InvalidInput(cat("signed distance field: voxel ", voxel_mm, " mm and band ", exterior_mm,
                           " / ", interior_mm, " mm must be positive"));
  const double band_mm = std::max(exterior_mm, interior_mm);
  if (mask.data.size() != mask.geom.n_voxels() || mask.count() == 0)
    throw InvalidInput("signed distance field: the mask is empty");
  const VolumeGeometry& g = mask.geom;
  // Carry the border slices on outward `pad` voxels (beyond the band), then one layer of air.
  Eigen::Vector3i pad;
  for (int a = 0; a < 3; ++a) pad[a] = static_cast<int>(std::ceil(band_mm / g.spacing_mm[a])) + 2;
  Volume field;
  field.geom = g;
  for (int a = 0; a < 3; ++a) field.geom.dims[a] = g.dims[a] + 2 * (pad[a] + 1);
  field.geom.origin_lps =
      g.origin_lps -
      g.direction * g.spacing_mm.cwiseProduct((pad.array() + 1).cast<double>().matrix());
  const Eigen::Vector3i& d = field.geom.dims;
  std::vector<float> raw(field.geom.n_voxels(), 0.0f);
  tbb::parallel_for(1, d[2] - 1, [&](int k) {
    for (int j = 1; j < d[1] - 1; ++j)
      for (int i = 1; i < d[0] - 1; ++i) {
        const int si = std::clamp(i - pad[0] - 1, 0, g.dims[0] - 1);
        const int sj = std::clamp(j - pad[1] - 1, 0, g.dims[1] - 1);
        const int sk = std::clamp(k - pad[2] - 1, 0, g.dims[2] - 1);
        raw[field.geom.linear(i, j, k)] = mask.at(si, sj, sk) ? 1.0f : 0.0f;
      }
  });
  // 3x3x3 box mean, separably.
  field.data = raw;
  std::vector<float> tmp(raw.size());
  for (int a = 0; a < 3; ++a) {
    std::vector<float>& src = a % 2 == 0 ? field.data : tmp;
    std::vector<float>& dst = a % 2 == 0 ? tmp : field.data;
    tbb::parallel_for(0, d[2], [&, a](int k) {
      for (int j = 0; j < d[1]; ++j)
        for (int i = 0; i < d[0]; ++i) {
          Eigen::Vector3i c(i, j, k);
          float s = 0;
          for (int o = -1; o <= 1; ++o) {
            Eigen::Vector3i n = c;
            n[a] += o;
            if (n[a] >= 0 && n[a] < d[a]) s += src[field.geom.linear(n[0], n[1], n[2])];
          }
          dst[field.geom.linear(i, j, k)] = s / 3.0f;
        }
    });
  }
  field.data.swap(tmp);  // three passes: the result is in tmp
  // The signed distance on the (padded) working grid. Near the surface, from the smoothed
  // occupancy s: across a boundary the 3-voxel box mean falls by a third per voxel, so
  // (0.5 - s) * 3 h is the distance to its 0.5 level (sub-voxel). Farther, where s is 0 or 1,
  // the exact distance transform of the mask (to the nearest voxel of the other side, less
  // half a voxel along the way there).
  Mask inside, outside_m;
  inside.geom = outside_m.geom = field.geom;
  inside.data.resize(raw.size());
  outside_m.data.resize(raw.size());
  for (std::size_t v = 0; v < raw.size(); ++v) {
    inside.data[v] = raw[v] > 0.5f ? 1 : 0;
    outside_m.data[v] = raw[v] > 0.5f ? 0 : 1;
  }
  const std::vector<float> to_inside = squared_distance_mm2(inside);
  const std::vector<float> to_outside = squared_distance_mm2(outside_m);
  const double h_min = g.spacing_mm.minCoeff(), h_mean = g.spacing_mm.mean();
  std::vector<float> phi(raw.size());
  tbb::parallel_for(std::size_t(0), raw.size(), [&](std::size_t v) {
    const float sm = field.data[v];
    if (sm > 1e-4f && sm < 1.0f - 1e-4f) {
      phi[v] = static_cast<float>((0.5 - sm) * 3.0 * h_mean);
    } else if (raw[v] > 0.5f) {
      phi[v] = -static_cast<float>(std::max(std::sqrt(to_outside[v]) - 0.5 * h_min, 1.5 * h_min));
    } else {
      phi[v] = static_cast<float>(std::max(std::sqrt(to_inside[v]) - 0.5 * h_min, 1.5 * h_min));
    }
  });
  // Sample it on cubes of voxel_mm (world space = LPS mm) over the padded grid's extent, within
  // the band; the rest are inactive tiles of +-background.
  const double background = std::max(exterior_mm, interior_mm);
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d ijk((c & 1) ? d[0] - 1 : 0, (c & 2) ? d[1] - 1 : 0,
                              (c & 4) ? d[2] - 1 : 0);
    const Eigen::Vector3d p = field.geom.index_to_lps(ijk);
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  initialize_vdb();
  const openvdb::CoordBBox box(openvdb::Coord(static_cast<int>(std::ceil(lo[0] / voxel_mm)),
                                              static_cast<int>(std::ceil(lo[1] / voxel_mm)),
                                              static_cast<int>(std::ceil(lo[2] / voxel_mm))),
                               openvdb::Coord(static_cast<int>(std::floor(hi[0] / voxel_mm)),
                                              static_cast<int>(std::floor(hi[1] / voxel_mm)),
                                              static_cast<int>(std::floor(hi[2] / voxel_mm))));
  openvdb::tools::Dense<float, openvdb::tools::LayoutXYZ> dense(box,
                                                                static_cast<float>(background));
  Volume phi_volume;
  phi_volume.geom = field.geom;
  phi_volume.data = std::move(phi);
  const openvdb::Coord b0 = box.min(), b1 = box.max();
  tbb::parallel_for(b0.z(), b1.z() + 1, [&](int z) {
    for (int y = b0.y(); y <= b1.y(); ++y)
      for (int x = b0.x(); x <= b1.x(); ++x) {
        const Eigen::Vector3d p(x * voxel_mm, y * voxel_mm, z * voxel_mm);
        const double value = sample_trilinear(phi_volume, phi_volume.lps_to_index(p),
                                              static_cast<float>(background));
        dense.setValue(openvdb::Coord(x, y, z),
                       static_cast<float>(std::clamp(value, -background, background)));
      }
  });
  auto grid = openvdb::FloatGrid::create(static_cast<float>(background));
  grid->setTransform(openvdb::math::Transform::createLinearTransform(voxel_mm));
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  openvdb::tools::copyFromDense(dense, *grid, 1e-6f);
  // Outside the band: inactive, then pruned into tiles of +-background.
  for (auto it = grid->tree().beginValueOn(); it; ++it) {
    const float value = *it;
    if (value >= static_cast<float>(exterior_mm) || value <= -static_cast<float>(interior_mm))
      it.setValueOff();
  }
  // The distances away from the surface solved again from its zero level (fast sweeping of the
  // Eikonal equation over the band): exact for the surface the near values place sub-voxel,
  // instead of the voxel staircase's distance transform.
  grid = openvdb::tools::sdfToSdf(*grid, 0.0f, 1);
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  openvdb::tools::pruneLevelSet(grid->tree());
  auto impl = std::make_shared<Impl>();
  impl->grid = grid;
  impl->voxel = voxel_mm;
  impl->exterior = background;
  impl->interior = background;
  SignedDistanceField f;
  f.impl_ = std::move(impl);
  return f;
}

SignedDistanceField SignedDistanceField::read(const std::filesystem::path& path) {
  initialize_vdb();
  {
    std::ifstream probe(path, std::ios::binary);
    if (!probe) throw IoError(cat(path.string(), ": cannot open the level set"));
  }
  openvdb::GridPtrVecPtr grids;
  try {
    openvdb::io::File file(path.string());
    file.open(false);
    grids = file.getGrids();
    file.close();
  } catch (const std::exception& e) {
    throw InvalidInput(cat(path.string(), ": not an OpenVDB level set (", e.what(),
                           "); rebuild it with `caps model tissue MODEL --force`"));
  }
  for (const auto& base : *grids) {
    auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
    if (!grid || grid->getGridClass() != openvdb::GRID_LEVEL_SET) continue;
    const openvdb::Vec3d vs = grid->voxelSize();
    if (!grid->transform().isLinear() || !(vs[0] > 0) || std::abs(vs[0] - vs[1]) > 1e-6 * vs[0] ||
        std::abs(vs[0] - vs[2]) > 1e-6 * vs[0])
      throw InvalidInput(cat(path.string(), ": the level set's voxels are not cubes"));
    const double bg = grid->background();
    if (!(bg > 0) || !std::isfinite(bg))
      throw InvalidInput(cat(path.string(), ": the level set's band (", bg, ") is not positive"));
    auto impl = std::make_shared<Impl>();
    impl->grid = grid;
    impl->voxel = vs[0];
    impl->exterior = bg;
    impl->interior = bg;
    for (const char* key : {"exterior_mm", "interior_mm"}) {
      const auto meta = (*grid)[key];
      if (!meta) continue;
      const auto* value = dynamic_cast<const openvdb::DoubleMetadata*>(meta.get());
      if (!value || !(value->value() > 0) || !std::isfinite(value->value())) continue;
      (key[0] == 'e' ? impl->exterior : impl->interior) = value->value();
    }
    SignedDistanceField f;
    f.impl_ = std::move(impl);
    return f;
  }
  throw InvalidInput(cat(path.string(), ": holds no float level-set grid"));
}

void SignedDistanceField::write(const std::filesystem::path& path, const std::string& name) const {
  if (!impl_) throw InvalidInput("signed distance field: nothing to write");
  initialize_vdb();
  openvdb::FloatGrid::Ptr grid = impl_->grid->deepCopy();
  grid->setName(name);
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  grid->insertMeta("units", openvdb::StringMetadata("mm, world space = patient LPS"));
  grid->insertMeta("created_by", openvdb::StringMetadata("caps"));
  grid->insertMeta("exterior_mm", openvdb::DoubleMetadata(impl_->exterior));
  grid->insertMeta("interior_mm", openvdb::DoubleMetadata(impl_->interior));
  write_file_atomic(path, [&](const std::filesystem::path& tmp) {
    try {
      openvdb::io::File file(tmp.string());
      file.write({grid});
      file.close();
    } catch (const std::exception& e) {
      throw IoError(cat(path.string(), ": cannot write the level set: ", e.what()));
    }
  });
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

Eigen::Vector3d SignedDistanceField::normal(const Eigen::Vector3d& p) const {
  const Eigen::Vector3d g = gradient(p);
  const double n = g.norm();
  return n > 1e-9 ? Eigen::Vector3d(g / n) : Eigen::Vector3d::Zero();
}

Eigen::Vector3d SignedDistanceField::closest_point(const Eigen::Vector3d& p) const {
  Eigen::Vector3d q = p;
  for (int it = 0; it < 5; ++it) {
    const double phi = (*this)(q);
    const Eigen::Vector3d n = normal(q);
    if (n.isZero()) break;
    const Eigen::Vector3d step = phi * n;
    q -= step;
    if (step.norm() < 0.01 * impl_->voxel) break;
  }
  return q;
}

double SignedDistanceField::voxel_mm() const { return impl_->voxel; }
double SignedDistanceField::exterior_mm() const { return impl_->exterior; }
double SignedDistanceField::interior_mm() const { return impl_->interior; }

std::size_t SignedDistanceField::n_active_voxels() const {
  return static_cast<std::size_t>(impl_->grid->activeVoxelCount());
}

}  // namespace caps

#include "caps/surface/range_mesh.hpp"

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"

namespace caps {

TriMesh range_mesh(const CylindricalMaps& maps, RangeSurface which,
                   const RangeMeshOptions& options) {
  const auto& g = maps.grid;
  const auto& r = which == RangeSurface::Skin ? maps.r_skin : maps.r_bone;
  if (g.n_theta < 3 || g.n_z < 2 || r.size() != g.size())
    throw InvalidInput(cat("range_mesh: the maps (", g.n_theta, " x ", g.n_z,
                           ") need at least 3 x 2 samples"));
  const int nt = g.n_theta, nz = g.n_z;
  const Eigen::Index n_grid = Eigen::Index(nt) * nz;
  TriMesh m;
  m.V.resize(n_grid + (options.close_poles ? 2 : 0), 3);
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < nt; ++j)
      m.V.row(Eigen::Index(k) * nt + j) =
          maps.axis.to_lps(deg_to_rad(g.theta_deg(j)), g.z_mm(k), std::max(0.0f, r[g.index(j, k)]))
              .transpose();
  const Eigen::Index n_quads = Eigen::Index(nt) * (nz - 1);
  m.F.resize(2 * n_quads + (options.close_poles ? 2 * nt : 0), 3);
  for (int k = 0; k + 1 < nz; ++k)
    for (int j = 0; j < nt; ++j) {
      const int j1 = (j + 1) % nt;
      const Eigen::Index q = Eigen::Index(k) * nt + j;
      const int a = k * nt + j, b = k * nt + j1, c = (k + 1) * nt + j1, d = (k + 1) * nt + j;
      // e_theta x e_z = e_r: (a, b, c) runs counter-clockwise seen from outside.
      m.F.row(2 * q) << a, b, c;
      m.F.row(2 * q + 1) << a, c, d;
    }
  if (options.close_poles) {
    const int bottom = static_cast<int>(n_grid), top = bottom + 1;
    m.V.row(bottom) = maps.axis.to_lps(0.0, g.z_mm(0), 0.0).transpose();
    m.V.row(top) = maps.axis.to_lps(0.0, g.z_mm(nz - 1), 0.0).transpose();
    for (int j = 0; j < nt; ++j) {
      const int j1 = (j + 1) % nt;
      m.F.row(2 * n_quads + j) << bottom, j1, j;  // seen from below
      m.F.row(2 * n_quads + nt + j) << top, (nz - 1) * nt + j, (nz - 1) * nt + j1;
    }
  }
  return m;
}

Eigen::Vector2i range_mesh_cell(const CylinderGrid& g, Eigen::Index f) {
  const Eigen::Index q = f / 2;
  if (f < 0 || q >= Eigen::Index(g.n_theta) * (g.n_z - 1)) return {-1, -1};
  return {static_cast<int>(q % g.n_theta), static_cast<int>(q / g.n_theta)};
}

}  // namespace caps

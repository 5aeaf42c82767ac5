#include "caps/fem/box.hpp"

#include <cmath>
#include <set>

#include "caps/core/error.hpp"
#include "caps/fem/elements.hpp"

namespace caps::fem {

Mesh make_box_mesh(const BoxOptions& o) {
  if (!o.size_mm.allFinite() || !(o.size_mm.minCoeff() > 0))
    throw InvalidInput(cat("box: size (", o.size_mm.transpose(), ") mm must be positive"));
  if (o.cells.minCoeff() < 1 || o.cells.maxCoeff() > 1000)
    throw InvalidInput(cat("box: cells (", o.cells.transpose(), ") must be in 1..1000"));
  const int nx = o.cells.x(), ny = o.cells.y(), nz = o.cells.z();
  const int sx = nx / 2, j0 = std::max(1, ny / 4), j1 = ny - j0;
  if (o.slot && (nx % 2 == 0 || nx < 3 || j1 <= j0))
    throw InvalidInput(cat("box: a slot needs an odd x cell count >= 3 and at least 3 y cells; got ",
                           o.cells.transpose()));
  const int Lx = 2 * nx + 1, Ly = 2 * ny + 1, Lz = 2 * nz + 1;
  auto lid = [&](int i, int j, int k) { return (static_cast<long>(k) * Ly + j) * Lx + i; };
  std::vector<int> node_of(static_cast<std::size_t>(Lx) * Ly * Lz, -1);
  std::vector<std::array<int, 20>> lattice_elems;
  std::vector<ElementType> types;
  const Eigen::MatrixX3d hexP = natural_nodes(ElementType::Hex20);
  const Eigen::MatrixX3d wedP = natural_nodes(ElementType::Wedge15);
  for (int cz = 0; cz < nz; ++cz)
    for (int cy = 0; cy < ny; ++cy)
      for (int cx = 0; cx < nx; ++cx) {
        if (o.slot && cx == sx && cy >= j0 && cy < j1) continue;
        const int bx = 2 * cx, by = 2 * cy, bz = 2 * cz;
        if (!o.wedges) {
          std::array<int, 20> e{};
          for (int a = 0; a < 20; ++a)
            e[a] = static_cast<int>(lid(bx + 1 + static_cast<int>(hexP(a, 0)),
                                        by + 1 + static_cast<int>(hexP(a, 1)),
                                        bz + 1 + static_cast<int>(hexP(a, 2))));
          lattice_elems.push_back(e);
          types.push_back(ElementType::Hex20);
        } else {
          // Two triangles (0,0)-(2,0)-(2,2) and (0,0)-(2,2)-(0,2), counter-clockwise in x-y.
          const int tri[2][3][2] = {{{0, 0}, {2, 0}, {2, 2}}, {{0, 0}, {2, 2}, {0, 2}}};
          for (const auto& t : tri) {
            std::array<int, 20> e{};
            for (int a = 0; a < 15; ++a) {
              const double r = wedP(a, 0), s = wedP(a, 1);
              const int i = static_cast<int>(std::lround(t[0][0] + r * (t[1][0] - t[0][0]) + s * (t[2][0] - t[0][0])));
              const int j = static_cast<int>(std::lround(t[0][1] + r * (t[1][1] - t[0][1]) + s * (t[2][1] - t[0][1])));
              e[a] = static_cast<int>(lid(bx + i, by + j, bz + 1 + static_cast<int>(wedP(a, 2))));
            }
            lattice_elems.push_back(e);
            types.push_back(ElementType::Wedge15);
          }
        }
      }
  Mesh m;
  std::vector<Eigen::Vector3d> pts;
  for (std::size_t e = 0; e < lattice_elems.size(); ++e) {
    Element el;
    el.type = types[e];
    el.layer = 0;
    for (int a = 0; a < n_element_nodes(el.type); ++a) {
      const long l = lattice_elems[e][a];
      if (node_of[l] < 0) {
        node_of[l] = static_cast<int>(pts.size());
        const long i = l % Lx, j = (l / Lx) % Ly, k = l / (static_cast<long>(Lx) * Ly);
        pts.emplace_back(o.size_mm.x() * i / (Lx - 1), o.size_mm.y() * j / (Ly - 1),
                         o.size_mm.z() * k / (Lz - 1));
      }
      el.nodes[a] = node_of[l];
    }
    m.elements.push_back(el);
  }
  m.nodes.resize(static_cast<Eigen::Index>(pts.size()), 3);
  for (std::size_t i = 0; i < pts.size(); ++i) m.nodes.row(static_cast<Eigen::Index>(i)) = pts[i];
  m.materials[0] = o.material;
  std::set<int> sutured;
  if (o.slot)
    for (int k = 0; k < Lz; ++k)
      for (int j = 2 * j0 + 1; j < 2 * j1; ++j) {
        const int a = node_of[lid(2 * sx, j, k)], b = node_of[lid(2 * sx + 2, j, k)];
        if (a < 0 || b < 0) continue;
        m.sutures.push_back({a, b});
        sutured.insert(a);
        sutured.insert(b);
      }
  if (o.fix_bottom)
    for (int j = 0; j < Ly; ++j)
      for (int i = 0; i < Lx; ++i) {
        const int n = node_of[lid(i, j, 0)];
        if (n >= 0 && !sutured.count(n)) m.fixed_nodes.push_back(n);
      }
  return m;
}

}  // namespace caps::fem

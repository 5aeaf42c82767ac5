#include "caps/fem/tet_mesh.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cstdint>
#include <unordered_map>

#include "caps/core/error.hpp"

namespace caps::fem {
namespace {

// Local corner pairs of the Tet10's mid-edge nodes 4-9 (mesh.hpp).
constexpr int kEdges[6][2] = {{0, 1}, {1, 2}, {2, 0}, {0, 3}, {1, 3}, {2, 3}};
// A tet whose 6 x volume is below this fraction of its longest edge cubed is degenerate (a
// regular tet has 0.118; a sliver from a mesh generator rarely goes below 1e-4).
constexpr double kDegenerateRelativeVolume = 1e-10;

}  // namespace

QuadraticTetMesh quadratic_tetrahedra(const Eigen::MatrixX3d& V, const Eigen::MatrixX4i& T,
                                      const Eigen::VectorXi& layers) {
  const Eigen::Index nv = V.rows(), nt = T.rows();
  if (layers.size() != nt)
    throw InvalidInput(cat("quadratic_tetrahedra: ", layers.size(), " layer ids for ", nt,
                           " tetrahedra; give one per tetrahedron"));
  for (Eigen::Index i = 0; i < nv; ++i)
    if (!V.row(i).allFinite())
      throw InvalidInput(cat("quadratic_tetrahedra: node ", i, " has a non-finite coordinate (",
                             V.row(i), ")"));
  QuadraticTetMesh out;
  out.elements.resize(static_cast<std::size_t>(nt));
  std::unordered_map<std::uint64_t, int> edge_id;
  edge_id.reserve(static_cast<std::size_t>(7 * nt / 5 + 16));  // about 1.2 edges per tet in a large mesh
  std::vector<std::array<int, 2>> edges;
  for (Eigen::Index t = 0; t < nt; ++t) {
    for (int a = 0; a < 4; ++a) {
      if (T(t, a) < 0 || T(t, a) >= nv)
        throw InvalidInput(cat("quadratic_tetrahedra: tetrahedron ", t, " refers to node ",
                               T(t, a), ", but node ids run 0..", nv - 1));
      for (int b = 0; b < a; ++b)
        if (T(t, a) == T(t, b))
          throw InvalidInput(cat("quadratic_tetrahedra: tetrahedron ", t, " (", T.row(t),
                                 ") uses node ", T(t, a), " twice"));
    }
    const Eigen::Vector3d x0 = V.row(T(t, 0)), x1 = V.row(T(t, 1)), x2 = V.row(T(t, 2)),
                          x3 = V.row(T(t, 3));
    const double vol6 = (x1 - x0).cross(x2 - x0).dot(x3 - x0);
    double longest = 0;
    for (const auto& e : kEdges)
      longest = std::max(longest, (V.row(T(t, e[0])) - V.row(T(t, e[1]))).norm());
    const double relative = vol6 / (longest * longest * longest);
    if (!(std::abs(relative) > kDegenerateRelativeVolume))
      throw InvalidInput(cat("quadratic_tetrahedra: tetrahedron ", t, " (nodes ", T.row(t),
                             ") is degenerate: volume ", vol6 / 6, " mm^3 with edges up to ",
                             longest, " mm; remove it or mesh again"));
    if (relative < 0)
      throw InvalidInput(cat("quadratic_tetrahedra: tetrahedron ", t, " (nodes ", T.row(t),
                             ") is inverted (volume ", vol6 / 6, " mm^3): the right-hand normal "
                             "of corners 0-1-2 must point towards corner 3; swap two corners"));
    Element& el = out.elements[static_cast<std::size_t>(t)];
    el.type = ElementType::Tet10;
    el.layer = layers[t];
    for (int a = 0; a < 4; ++a) el.nodes[a] = T(t, a);
    for (int k = 0; k < 6; ++k) {
      const int i = std::min(T(t, kEdges[k][0]), T(t, kEdges[k][1]));
      const int j = std::max(T(t, kEdges[k][0]), T(t, kEdges[k][1]));
      const std::uint64_t key = static_cast<std::uint64_t>(i) * static_cast<std::uint64_t>(nv) +
                                static_cast<std::uint64_t>(j);
      const auto [it, added] = edge_id.try_emplace(key, static_cast<int>(edges.size()));
      if (added) edges.push_back({i, j});
      el.nodes[4 + k] = static_cast<int>(nv) + it->second;
    }
  }
  const auto ne = static_cast<Eigen::Index>(edges.size());
  out.nodes.resize(nv + ne, 3);
  out.nodes.topRows(nv) = V;
  out.edges.resize(ne, 2);
  for (Eigen::Index k = 0; k < ne; ++k) {
    const auto& e = edges[static_cast<std::size_t>(k)];
    out.edges.row(k) << e[0], e[1];
    out.nodes.row(nv + k) = 0.5 * (V.row(e[0]) + V.row(e[1]));
  }
  return out;
}

QuadraticTetMesh quadratic_tetrahedra(const Eigen::MatrixX3d& V, const Eigen::MatrixX4i& T,
                                      int layer) {
  return quadratic_tetrahedra(V, T, Eigen::VectorXi::Constant(T.rows(), layer));
}

}  // namespace caps::fem

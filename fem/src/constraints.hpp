#pragma once
// Internal: maps every node dof to a reduced equation after eliminating fixed dofs and sutures.

#include <Eigen/Core>
#include <algorithm>
#include <numeric>
#include <vector>

#include "caps/core/union_find.hpp"
#include "caps/fem/mesh.hpp"

namespace caps::fem::detail {

using caps::UnionFind;

/// u_full = T q + g: dof d is q[eq[d]] + g[d] when eq[d] >= 0, or prescribed g[d] otherwise.
struct DofMap {
  std::vector<int> eq;               ///< 3N
  Eigen::VectorXd g;                 ///< 3N offsets / prescribed values (mm)
  int n_eq = 0;
  std::vector<int> group;            ///< node -> suture group id, -1 if not sutured
  std::vector<std::vector<int>> groups;  ///< members of each suture group
  std::vector<char> used;            ///< node is referenced by an element
  std::vector<char> constrained;     ///< node has a prescribed dof or a suture
  /// Equations come in blocks of up to three consecutive ones, one block per free node or
  /// suture group: block b is equations block_start[b] .. block_start[b+1]-1.
  std::vector<int> block_start;
  std::vector<int> node_block;       ///< node -> its block, -1 if every dof is prescribed
  /// Per Mesh::ties entry, the penalty k (N/mm) of its energy k/2 |u_s - sum w u_m|^2
  /// (tie_penalty()).
  std::vector<double> tie_stiffness;
};

/// The tie penalty factor: k = kTiePenalty E h for a tie whose slave and masters belong to
/// elements of Young's modulus (Material::stiffness_scale_mpa()) up to E and size up to h (mm).
/// An element's stiffness is about E h (N/mm) and a tied node carries at most a few elements'
/// forces, so the tie gives way by about 1e-6 of the displacement (measured in
/// tests/test_fem_tie.cpp; docs/fem.md, "Ties and sliding on the bone").
inline constexpr double kTiePenalty = 1e6;

/// Per Mesh::ties entry, its penalty k (N/mm): kTiePenalty times the largest E h over the
/// elements that use the slave or a master (h: the largest extent of the element's nodes' box).
std::vector<double> tie_penalties(const Mesh& mesh);

/// Builds the map; throws InvalidInput for conflicting constraints, sutures on nodes that are
/// not in any element and parts with no support in some direction.
DofMap build_dof_map(const Mesh& mesh);

/// The direction a sliding entry is held along in the small-strain solve and the CalculiX deck
/// (the linearisation at the start): grad phi(X) / |grad phi(X)| for an entry on
/// Mesh::sliding_surface, its `normal` otherwise.
Eigen::Vector3d start_normal(const Mesh& mesh, const SlidingNode& s);

/// The first node dof (3 node + component) that reduced equation `e` solves for, -1 if none.
int equation_dof(const DofMap& map, int e);

/// Names reduced equation `e` for messages: "node 12 (x)".
std::string describe_equation(const DofMap& map, int e);

}  // namespace caps::fem::detail

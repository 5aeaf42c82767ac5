#include "caps/fem/mesh.hpp"

#include <cctype>
#include <algorithm>
#include <cmath>

#include "caps/core/error.hpp"

namespace caps::fem {

ImplicitSurface::~ImplicitSurface() = default;

namespace {

template <class CheckNode>
void validate_ties(const Mesh& mesh, const std::string& where, const CheckNode& check_node) {
  std::vector<char> slave(static_cast<std::size_t>(mesh.n_nodes()), 0);
  for (std::size_t i = 0; i < mesh.ties.size(); ++i) {
    const TiedNode& t = mesh.ties[i];
    const auto item = [&] { return cat("tie ", i, " (slave node ", t.node, ")"); };
    check_node(t.node, [&] { return cat("tie ", i); });
    if (slave[t.node]++)
      throw InvalidInput(cat(where, ": ", item(), " ties a node that an earlier tie already ties; "
                             "tie each slave once"));
    if (t.masters.empty() || t.masters.size() != t.weights.size())
      throw InvalidInput(cat(where, ": ", item(), " has ", t.masters.size(), " masters and ",
                             t.weights.size(), " weights; it needs one weight per master, at least one"));
    double sum = 0;
    for (std::size_t k = 0; k < t.masters.size(); ++k) {
      check_node(t.masters[k], [&] { return cat(item(), " master ", k); });
      if (t.masters[k] == t.node)
        throw InvalidInput(cat(where, ": ", item(), " is tied to itself; a slave's masters are "
                               "the nodes of another element"));
      if (std::find(t.masters.begin(), t.masters.begin() + static_cast<long>(k), t.masters[k]) !=
          t.masters.begin() + static_cast<long>(k))
        throw InvalidInput(cat(where, ": ", item(), " names master node ", t.masters[k], " twice"));
      if (!std::isfinite(t.weights[k]))
        throw InvalidInput(cat(where, ": ", item(), " has a non-finite weight"));
      sum += t.weights[k];
    }
    if (!(std::abs(sum - 1) <= 1e-6))
      throw InvalidInput(cat(where, ": ", item(), " has weights summing to ", sum, ", not 1: the "
                             "weights are the master element's shape functions at the slave "
                             "(fem::tie_nodes())"));
  }
}

}  // namespace

void validate(const Mesh& mesh, const std::string& where) {
  const Eigen::Index n = mesh.n_nodes();
  if (n == 0) throw InvalidInput(cat(where, ": the mesh has no nodes"));
  if (mesh.elements.empty()) throw InvalidInput(cat(where, ": the mesh has no elements"));
  for (Eigen::Index i = 0; i < n; ++i)
    if (!mesh.nodes.row(i).allFinite())
      throw InvalidInput(cat(where, ": node ", i, " has a non-finite coordinate (",
                             mesh.nodes.row(i), "); fix or remove it"));
  // `item` names the entry; it is only formatted for the message (validation runs on every solve).
  auto check_node = [&](long id, auto&& item) {
    if (id < 0 || id >= n)
      throw InvalidInput(cat(where, ": ", item(), " refers to node ", id,
                             ", but node ids run 0..", n - 1));
  };
  for (std::size_t e = 0; e < mesh.elements.size(); ++e) {
    const Element& el = mesh.elements[e];
    const auto item = [&] { return cat("element ", e, " (", element_type_name(el.type), ")"); };
    if (el.type != ElementType::Hex20 && el.type != ElementType::Wedge15 &&
        el.type != ElementType::Tet10)
      throw InvalidInput(cat(where, ": element ", e, " has an unknown type"));
    std::array<int, 20> sorted = el.nodes;
    for (int a = 0; a < el.n_nodes(); ++a)
      check_node(el.nodes[a], [&] { return cat(item(), " local node ", a); });
    std::sort(sorted.begin(), sorted.begin() + el.n_nodes());
    const auto dup = std::adjacent_find(sorted.begin(), sorted.begin() + el.n_nodes());
    if (dup != sorted.begin() + el.n_nodes())
      throw InvalidInput(cat(where, ": ", item(), " uses node ", *dup,
                             " twice; a collapsed hexahedron must be written as a Wedge15"));
    const auto material = mesh.materials.find(el.layer);
    if (material == mesh.materials.end() || !material->second)
      throw InvalidInput(cat(where, ": ", item(), " has layer ", el.layer,
                             " but no material is given for that layer"));
  }
  for (std::size_t i = 0; i < mesh.fixed_nodes.size(); ++i)
    check_node(mesh.fixed_nodes[i], [&] { return cat("fixed node entry ", i); });
  for (std::size_t i = 0; i < mesh.fixed_dofs.size(); ++i) {
    const FixedDof& f = mesh.fixed_dofs[i];
    check_node(f.node, [&] { return cat("fixed dof entry ", i); });
    if (f.component < 0 || f.component > 2)
      throw InvalidInput(cat(where, ": fixed dof entry ", i, " has component ", f.component,
                             "; use 0 (x), 1 (y) or 2 (z)"));
    if (!std::isfinite(f.value_mm))
      throw InvalidInput(cat(where, ": fixed dof entry ", i, " (node ", f.node,
                             ") has a non-finite value"));
  }
  const auto n_elements = static_cast<long>(mesh.elements.size());
  for (std::size_t f = 0; f < mesh.flaps.size(); ++f)
    for (const int e : mesh.flaps[f])
      if (e < 0 || e >= n_elements)
        throw InvalidInput(cat(where, ": flap ", f, " refers to element ", e,
                               ", but element ids run 0..", n_elements - 1));
  for (std::size_t i = 0; i < mesh.sliding.size(); ++i) {
    const SlidingNode& s = mesh.sliding[i];
    check_node(s.node, [&] { return cat("sliding node entry ", i); });
    if (!s.normal.allFinite() || std::abs(s.normal.norm() - 1) > 1e-6 ||
        !(s.stiffness_n_per_mm > 0) || !std::isfinite(s.stiffness_n_per_mm) || s.stiffness_n_per_mm > 1e12)
      throw InvalidInput(cat(where, ": sliding node entry ", i, " (node ", s.node,
                             ") needs a unit normal and a stiffness in (0, 1e12] N/mm"));
  }
  for (std::size_t i = 0; i < mesh.sliding.size(); ++i) {
    const SlidingNode& s = mesh.sliding[i];
    if (!s.on_surface || !mesh.sliding_surface) continue;
    const Eigen::Vector3d x = mesh.nodes.row(s.node).transpose();
    const Eigen::Vector3d g = mesh.sliding_surface->gradient(x);
    if (!std::isfinite(mesh.sliding_surface->distance(x)) || !g.allFinite() || !(g.norm() > 1e-9))
      throw InvalidInput(cat(where, ": sliding node entry ", i, " (node ", s.node, ") slides on the '",
                             mesh.sliding_surface_name, "' surface, whose level set has no finite "
                             "value or nonzero gradient there; the node is outside the field"));
  }
  validate_ties(mesh, where, check_node);
  for (const auto& node_set : mesh.node_sets) {
    const std::string& name = node_set.first;  // not a structured binding: a lambda captures it
    const auto& ids = node_set.second;
    const bool ok_name = !name.empty() && name.size() <= 64 &&
                         std::all_of(name.begin(), name.end(), [](char c) {
                           return std::isalnum(static_cast<unsigned char>(c)) || c == '_';
                         });
    if (!ok_name)
      throw InvalidInput(cat(where, ": node set '", name, "': name it with 1-64 letters, digits "
                             "and underscores"));
    for (std::size_t k = 0; k < ids.size(); ++k)
      check_node(ids[k], [&] { return cat("node set ", name, " entry ", k); });
  }
  for (std::size_t i = 0; i < mesh.loads.size(); ++i) {
    check_node(mesh.loads[i].node, [&] { return cat("load entry ", i); });
    if (!mesh.loads[i].force_n.allFinite())
      throw InvalidInput(cat(where, ": load entry ", i, " (node ", mesh.loads[i].node,
                             ") has a non-finite force"));
  }
  for (std::size_t i = 0; i < mesh.sutures.size(); ++i) {
    const SuturePair& s = mesh.sutures[i];
    check_node(s.a, [&] { return cat("suture ", i); });
    check_node(s.b, [&] { return cat("suture ", i); });
    if (s.a == s.b)
      throw InvalidInput(cat(where, ": suture ", i, " joins node ", s.a,
                             " to itself; a suture needs two different nodes"));
  }
}

Element wedge_from_collapsed_hex(const std::array<int, 20>& h, int layer) {
  if (h[2] != h[3] || h[2] != h[10] || h[18] != h[19] || h[6] != h[7] || h[6] != h[14])
    throw InvalidInput(cat("collapsed hexahedron: nodes 2, 10, 3 (", h[2], ", ", h[10], ", ",
                           h[3], "), 18, 19 (", h[18], ", ", h[19], ") and 6, 14, 7 (", h[6],
                           ", ", h[14], ", ", h[7], ") must each share one node id"));
  Element w;
  w.type = ElementType::Wedge15;
  w.layer = layer;
  const int map[15] = {0, 1, 2, 4, 5, 6, 8, 9, 11, 12, 13, 15, 16, 17, 18};
  for (int k = 0; k < 15; ++k) w.nodes[k] = h[map[k]];
  return w;
}

}  // namespace caps::fem

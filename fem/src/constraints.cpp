#include "constraints.hpp"

#include <cmath>
#include <numeric>

#include "caps/core/error.hpp"

namespace caps::fem::detail {
namespace {

struct UnionFind {
  std::vector<int> p;
  explicit UnionFind(int n) : p(static_cast<std::size_t>(n)) { std::iota(p.begin(), p.end(), 0); }
  int find(int x) {
    while (p[x] != x) x = p[x] = p[p[x]];
    return x;
  }
  void unite(int a, int b) {
    a = find(a);
    b = find(b);
    if (a != b) p[std::max(a, b)] = std::min(a, b);
  }
};

const char* kAxis[3] = {"x", "y", "z"};

}  // namespace

std::string describe_equation(const DofMap& map, int e) {
  for (std::size_t d = 0; d < map.eq.size(); ++d)
    if (map.eq[d] == e) return cat("node ", d / 3, " (", kAxis[d % 3], ")");
  return cat("equation ", e);
}

DofMap build_dof_map(const Mesh& mesh) {
  const int n = static_cast<int>(mesh.n_nodes());
  DofMap m;
  m.used.assign(n, 0);
  for (const Element& el : mesh.elements)
    for (int a = 0; a < el.n_nodes(); ++a) m.used[el.nodes[a]] = 1;

  // Prescribed values per dof (NaN = free).
  std::vector<double> fixed(3 * static_cast<std::size_t>(n), NAN);
  auto set_fixed = [&](int node, int c, double v, const std::string& item) {
    double& f = fixed[3 * node + c];
    if (!std::isnan(f) && std::abs(f - v) > 1e-12 * (1 + std::abs(v)))
      throw InvalidInput(cat(item, ": node ", node, " (", kAxis[c], ") is fixed twice, to ", f,
                             " and ", v, " mm; keep one"));
    f = v;
  };
  for (int node : mesh.fixed_nodes)
    for (int c = 0; c < 3; ++c) set_fixed(node, c, 0.0, "fixed nodes");
  for (const FixedDof& f : mesh.fixed_dofs) set_fixed(f.node, f.component, f.value_mm, "fixed dofs");

  UnionFind sut(n);
  for (std::size_t i = 0; i < mesh.sutures.size(); ++i) {
    const SuturePair& s = mesh.sutures[i];
    for (int node : {s.a, s.b})
      if (!m.used[node])
        throw InvalidInput(cat("suture ", i, ": node ", node,
                               " is not part of any element; suture nodes of the mesh"));
    sut.unite(s.a, s.b);
  }
  m.group.assign(n, -1);
  std::vector<int> group_of_root(n, -1);
  for (const SuturePair& s : mesh.sutures)
    for (int node : {s.a, s.b}) {
      const int r = sut.find(node);
      if (group_of_root[r] < 0) {
        group_of_root[r] = static_cast<int>(m.groups.size());
        m.groups.emplace_back();
      }
      if (m.group[node] < 0) {
        m.group[node] = group_of_root[r];
        m.groups[group_of_root[r]].push_back(node);
      }
    }

  m.eq.assign(3 * static_cast<std::size_t>(n), -1);
  m.g = Eigen::VectorXd::Zero(3 * n);
  // Per group and component: common final position if prescribed, else its equation.
  std::vector<double> group_pos(3 * m.groups.size(), NAN);
  std::vector<int> group_eq(3 * m.groups.size(), -1);
  for (std::size_t gi = 0; gi < m.groups.size(); ++gi)
    for (int c = 0; c < 3; ++c)
      for (int node : m.groups[gi]) {
        const double f = fixed[3 * node + c];
        if (std::isnan(f)) continue;
        const double p = mesh.nodes(node, c) + f;
        double& gp = group_pos[3 * gi + c];
        if (!std::isnan(gp) && std::abs(gp - p) > 1e-9 * (1 + std::abs(p)))
          throw InvalidInput(cat("sutures join node ", node, ", fixed so that its final ",
                                 kAxis[c], " is ", p, " mm, to a node whose final ", kAxis[c],
                                 " is fixed at ", gp, " mm; they cannot meet: unfix one of them"));
        gp = p;
      }
  for (int node = 0; node < n; ++node) {
    if (!m.used[node]) continue;  // orphan nodes keep u = 0 and get no equation
    const int gi = m.group[node];
    for (int c = 0; c < 3; ++c) {
      const std::size_t d = 3 * static_cast<std::size_t>(node) + c;
      if (gi < 0) {
        if (std::isnan(fixed[d]))
          m.eq[d] = m.n_eq++;
        else
          m.g[d] = fixed[d];
        continue;
      }
      const double gp = group_pos[3 * gi + c];
      if (!std::isnan(gp)) {
        m.g[d] = gp - mesh.nodes(node, c);
        continue;
      }
      int& ge = group_eq[3 * gi + c];
      if (ge < 0) ge = m.n_eq++;
      m.eq[d] = ge;
      const int master = m.groups[gi].front();
      m.g[d] = mesh.nodes(master, c) - mesh.nodes(node, c);  // u_n = u_master + x_m - x_n
    }
  }
  m.constrained.assign(n, 0);
  for (int node = 0; node < n; ++node)
    m.constrained[node] = m.used[node] && (m.group[node] >= 0 || m.eq[3 * node] < 0 ||
                                          m.eq[3 * node + 1] < 0 || m.eq[3 * node + 2] < 0);

  // Every connected part (elements + sutures) needs support in x, y and z; rotations are
  // caught later by the factorization.
  UnionFind part(n);
  for (const Element& el : mesh.elements)
    for (int a = 1; a < el.n_nodes(); ++a) part.unite(el.nodes[0], el.nodes[a]);
  for (const SuturePair& s : mesh.sutures) part.unite(s.a, s.b);
  std::vector<int> support(3 * static_cast<std::size_t>(n), 0), size(n, 0);
  for (int node = 0; node < n; ++node) {
    if (!m.used[node]) continue;
    const int r = part.find(node);
    ++size[r];
    for (int c = 0; c < 3; ++c)
      if (m.eq[3 * node + c] < 0) support[3 * r + c] = 1;
  }
  for (int r = 0; r < n; ++r)
    for (int c = 0; c < 3; ++c)
      if (size[r] > 0 && !support[3 * r + c])
        throw InvalidInput(cat("the mesh is under-constrained: the part containing node ", r, " (",
                               size[r], " nodes) has no fixed ", kAxis[c],
                               " displacement and can move freely; fix some of its nodes (the "
                               "bottom layer, on bone) or suture it to a fixed part"));
  return m;
}

}  // namespace caps::fem::detail

#include "constraints.hpp"

#include <cmath>
#include <numeric>

#include <Eigen/Eigenvalues>

#include "caps/core/error.hpp"

namespace caps::fem::detail {
namespace {

const char* kAxis[3] = {"x", "y", "z"};

// Every part must also be held against rigid rotation: the six rigid motions u = t + w × x of
// a part must all violate some constraint, a prescribed dof (u_c = 0) or a suture between two
// of its nodes (u_a = u_b, so w × (x_a - x_b) = 0). With C the constraint rows over (t, w), in
// coordinates centred on the part and scaled by its size, a free rotation is a null vector of
// C^T C. This is exact for meshes without mechanisms and does not depend on the pivots of a
// factorization (which, for a singular matrix, are round-off of either sign).
void check_rotations(const Mesh& mesh, const DofMap& m, UnionFind& part, const std::vector<int>& size) {
  const int n = static_cast<int>(mesh.n_nodes());
  std::vector<int> index(n, -1);
  std::vector<Eigen::Vector3d> centre;
  std::vector<double> extent;
  std::vector<int> root;
  for (int node = 0; node < n; ++node)
    if (m.used[node] && index[part.find(node)] < 0) {
      index[part.find(node)] = static_cast<int>(root.size());
      root.push_back(part.find(node));
    }
  const std::size_t n_parts = root.size();
  centre.assign(n_parts, Eigen::Vector3d::Zero());
  Eigen::MatrixX3d lo = Eigen::MatrixX3d::Constant(n_parts, 3, INFINITY), hi = -lo;
  for (int node = 0; node < n; ++node) {
    if (!m.used[node]) continue;
    const int p = index[part.find(node)];
    centre[p] += mesh.nodes.row(node).transpose() / size[root[p]];
    lo.row(p) = lo.row(p).cwiseMin(mesh.nodes.row(node));
    hi.row(p) = hi.row(p).cwiseMax(mesh.nodes.row(node));
  }
  for (std::size_t p = 0; p < n_parts; ++p) extent.push_back(std::max((hi.row(p) - lo.row(p)).norm(), 1e-300));
  std::vector<Eigen::Matrix<double, 6, 6>> CtC(n_parts, Eigen::Matrix<double, 6, 6>::Zero());
  auto add_row = [&](int p, const Eigen::Matrix<double, 6, 1>& row) { CtC[p] += row * row.transpose(); };
  for (int node = 0; node < n; ++node) {
    if (!m.used[node]) continue;
    const int p = index[part.find(node)];
    const Eigen::Vector3d x = (mesh.nodes.row(node).transpose() - centre[p]) / extent[p];
    for (int c = 0; c < 3; ++c) {
      if (m.eq[3 * node + c] >= 0 || m.group[node] >= 0) continue;  // free, or sutured (below)
      Eigen::Matrix<double, 6, 1> row = Eigen::Matrix<double, 6, 1>::Zero();
      row[c] = 1;
      for (int j = 0; j < 3; ++j) row[3 + j] = Eigen::Vector3d::Unit(j).cross(x)[c];
      add_row(p, row);
    }
  }
  // A suture group whose position is prescribed holds each member like a fixed dof; the pairs
  // hold the part through their separations.
  for (std::size_t gi = 0; gi < m.groups.size(); ++gi)
    for (int node : m.groups[gi]) {
      const int p = index[part.find(node)];
      const Eigen::Vector3d x = (mesh.nodes.row(node).transpose() - centre[p]) / extent[p];
      for (int c = 0; c < 3; ++c) {
        if (m.eq[3 * node + c] >= 0) continue;
        Eigen::Matrix<double, 6, 1> row = Eigen::Matrix<double, 6, 1>::Zero();
        row[c] = 1;
        for (int j = 0; j < 3; ++j) row[3 + j] = Eigen::Vector3d::Unit(j).cross(x)[c];
        add_row(p, row);
      }
    }
  for (const SuturePair& s : mesh.sutures) {
    const int p = index[part.find(s.a)];
    const Eigen::Vector3d d = (mesh.nodes.row(s.a) - mesh.nodes.row(s.b)).transpose() / extent[p];
    for (int c = 0; c < 3; ++c) {
      Eigen::Matrix<double, 6, 1> row = Eigen::Matrix<double, 6, 1>::Zero();
      for (int j = 0; j < 3; ++j) row[3 + j] = Eigen::Vector3d::Unit(j).cross(d)[c];
      add_row(p, row);
    }
  }
  for (std::size_t p = 0; p < n_parts; ++p) {
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> es(CtC[p]);
    if (es.eigenvalues()[0] > 1e-10 * std::max(es.eigenvalues()[5], 1.0)) continue;
    Eigen::Vector3d w = es.eigenvectors().col(0).tail<3>().normalized();
    Eigen::Index big;
    w.cwiseAbs().maxCoeff(&big);
    if (w[big] < 0) w = -w;
    for (int c = 0; c < 3; ++c) w[c] = std::round(w[c] * 1e3) / 1e3 + 0.0;  // no "-0"
    throw InvalidInput(cat(
        "the mesh is under-constrained: the part containing node ", root[p], " (", size[root[p]],
        " nodes) can still rotate about the axis (", w.x(), ", ", w.y(), ", ", w.z(),
        "), the stiffness matrix is singular; fix at least three non-collinear nodes of it (the "
        "bottom layer, on bone) or suture it to a fixed part"));
  }
}

// A tie holds a slave node of an element to nodes of other elements. Its slave is moved only by
// the tie: a prescribed or sutured slave is refused (the CalculiX deck writes the tie as an
// *EQUATION whose dependent dofs are the slave's, which may be neither prescribed nor another
// equation's dependent; a sliding node's equation has one of its dofs as the dependent).
void check_ties(const Mesh& mesh, const DofMap& m) {
  if (mesh.ties.empty()) return;
  std::vector<char> sliding(static_cast<std::size_t>(mesh.n_nodes()), 0);
  for (const SlidingNode& s : mesh.sliding) sliding[s.node] = 1;
  for (std::size_t i = 0; i < mesh.ties.size(); ++i) {
    const TiedNode& t = mesh.ties[i];
    if (!m.used[t.node])
      throw InvalidInput(cat("tie ", i, ": slave node ", t.node, " is not part of any element; tie "
                             "nodes of the mesh"));
    for (int master : t.masters)
      if (!m.used[master])
        throw InvalidInput(cat("tie ", i, ": master node ", master, " is not part of any element"));
    if (m.group[t.node] >= 0)
      throw InvalidInput(cat("tie ", i, ": slave node ", t.node, " is also sutured; a tied node "
                             "moves with its masters: suture other nodes or leave it untied"));
    if (sliding[t.node])
      throw InvalidInput(cat("tie ", i, ": slave node ", t.node, " also slides; a tied node "
                             "moves with its masters: leave it untied or not sliding"));
    for (int c = 0; c < 3; ++c)
      if (m.eq[3 * static_cast<std::size_t>(t.node) + c] < 0)
        throw InvalidInput(cat("tie ", i, ": slave node ", t.node, " (", kAxis[c], ") is also "
                               "prescribed; a tied node moves with its masters: unfix it or leave "
                               "it untied"));
  }
}

}  // namespace

Eigen::Vector3d start_normal(const Mesh& mesh, const SlidingNode& s) {
  if (!s.on_surface || !mesh.sliding_surface) return s.normal;
  return mesh.sliding_surface->gradient(mesh.nodes.row(s.node).transpose()).normalized();
}

std::vector<double> tie_penalties(const Mesh& mesh) {
  if (mesh.ties.empty()) return {};
  const Eigen::Index n = mesh.n_nodes();
  Eigen::VectorXd node_scale = Eigen::VectorXd::Zero(n);  // largest E h of the node's elements (N/mm)
  for (const Element& el : mesh.elements) {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
    for (int a = 0; a < el.n_nodes(); ++a) {
      lo = lo.cwiseMin(mesh.nodes.row(el.nodes[a]).transpose());
      hi = hi.cwiseMax(mesh.nodes.row(el.nodes[a]).transpose());
    }
    const double scale = mesh.materials.at(el.layer)->stiffness_scale_mpa() * (hi - lo).maxCoeff();
    for (int a = 0; a < el.n_nodes(); ++a)
      node_scale[el.nodes[a]] = std::max(node_scale[el.nodes[a]], scale);
  }
  std::vector<double> k(mesh.ties.size());
  for (std::size_t i = 0; i < mesh.ties.size(); ++i) {
    double scale = node_scale[mesh.ties[i].node];
    for (int master : mesh.ties[i].masters) scale = std::max(scale, node_scale[master]);
    k[i] = kTiePenalty * scale;
  }
  return k;
}

int equation_dof(const DofMap& map, int e) {
  for (std::size_t d = 0; d < map.eq.size(); ++d)
    if (map.eq[d] == e) return static_cast<int>(d);
  return -1;
}

std::string describe_equation(const DofMap& map, int e) {
  const int d = equation_dof(map, e);
  if (d >= 0) return cat("node ", d / 3, " (", kAxis[d % 3], ")");
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
  m.block_start.assign(1, 0);
  m.node_block.assign(n, -1);
  std::vector<int> group_block(m.groups.size(), -1);
  for (int node = 0; node < n; ++node) {
    if (!m.used[node]) continue;  // orphan nodes keep u = 0 and get no equation
    const int gi = m.group[node];
    const int n_eq_before = m.n_eq;
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
    if (m.n_eq > n_eq_before) {  // this node opened a block (its own or its group's)
      m.node_block[node] = static_cast<int>(m.block_start.size()) - 1;
      m.block_start.push_back(m.n_eq);
      if (gi >= 0) group_block[gi] = m.node_block[node];
    } else if (gi >= 0) {
      m.node_block[node] = group_block[gi];  // -1 when the whole group is prescribed
    }
  }
  m.constrained.assign(n, 0);
  for (int node = 0; node < n; ++node)
    m.constrained[node] = m.used[node] && (m.group[node] >= 0 || m.eq[3 * node] < 0 ||
                                          m.eq[3 * node + 1] < 0 || m.eq[3 * node + 2] < 0);

  check_ties(mesh, m);
  m.tie_stiffness = tie_penalties(mesh);

  // Every connected part (elements, sutures and ties) needs support in x, y and z, and against
  // rotations (check_rotations). A tie holds no rigid motion of the parts it joins (u_s =
  // sum w u_m for any rigid motion of both, the weights reproducing it), so it joins parts but
  // adds no rows there.
  UnionFind part(n);
  for (const Element& el : mesh.elements)
    for (int a = 1; a < el.n_nodes(); ++a) part.unite(el.nodes[0], el.nodes[a]);
  for (const SuturePair& s : mesh.sutures) part.unite(s.a, s.b);
  for (const TiedNode& t : mesh.ties)
    for (int master : t.masters) part.unite(t.node, master);
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
  check_rotations(mesh, m, part, size);
  return m;
}

}  // namespace caps::fem::detail

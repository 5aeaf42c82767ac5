#include "closing_path.hpp"

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <cmath>
#include <numbers>

namespace caps::fem::detail {
namespace {

// (R(angle about axis) - I) v
Eigen::Vector3d turn_minus_identity(const Eigen::Vector3d& axis, double angle, const Eigen::Vector3d& v) {
  return Eigen::AngleAxisd(angle, axis) * v - v;
}

}  // namespace

ClosingPath::ClosingPath(const Mesh& mesh, const DofMap& map) : mesh_(mesh), map_(map) {
  const int n = static_cast<int>(mesh.n_nodes());
  const int n_flaps = static_cast<int>(mesh.flaps.size());
  motions_.assign(static_cast<std::size_t>(n_flaps), Motion{});
  rotations_deg_.assign(static_cast<std::size_t>(n_flaps), 0.0);
  if (n_flaps == 0 || map.groups.empty()) return;

  // A node lies on a flap when every element around it belongs to that flap: the nodes of the
  // flap's cut edges, not those of its base, which the surrounding skin shares.
  constexpr int kUnseen = -2;
  std::vector<int> element_flap(mesh.n_elements(), -1);
  for (int f = 0; f < n_flaps; ++f)
    for (int e : mesh.flaps[static_cast<std::size_t>(f)])
      if (e >= 0 && static_cast<std::size_t>(e) < mesh.n_elements()) element_flap[static_cast<std::size_t>(e)] = f;
  node_flap_.assign(static_cast<std::size_t>(n), kUnseen);
  for (std::size_t e = 0; e < mesh.n_elements(); ++e) {
    const Element& el = mesh.elements[e];
    for (int a = 0; a < el.n_nodes(); ++a) {
      int& nf = node_flap_[static_cast<std::size_t>(el.nodes[a])];
      nf = nf == kUnseen ? element_flap[e] : (nf == element_flap[e] ? nf : -1);
    }
  }
  for (int& nf : node_flap_)
    if (nf == kUnseen) nf = -1;

  // Each flap's rigid motion (Kabsch) from its sutured nodes to the mean of their partners that
  // are not on a flap (the surrounding skin, where the flap is laid). Partners on the other flap
  // move themselves and are left out of the fit.
  std::vector<std::vector<Eigen::Vector3d>> from(static_cast<std::size_t>(n_flaps)), to(from.size());
  for (const auto& members : map.groups) {
    Eigen::Vector3d target = Eigen::Vector3d::Zero();
    int n_fixed = 0;
    for (int m : members)
      if (node_flap_[static_cast<std::size_t>(m)] < 0) {
        target += mesh.nodes.row(m).transpose();
        ++n_fixed;
      }
    if (n_fixed == 0) continue;
    target /= n_fixed;
    for (int m : members)
      if (const int f = node_flap_[static_cast<std::size_t>(m)]; f >= 0) {
        from[static_cast<std::size_t>(f)].push_back(mesh.nodes.row(m).transpose());
        to[static_cast<std::size_t>(f)].push_back(target);
      }
  }
  for (int f = 0; f < n_flaps; ++f) {
    const auto& P = from[static_cast<std::size_t>(f)];
    const auto& Q = to[static_cast<std::size_t>(f)];
    if (P.size() < 3) continue;
    Eigen::Vector3d pc = Eigen::Vector3d::Zero(), qc = Eigen::Vector3d::Zero();
    for (std::size_t i = 0; i < P.size(); ++i) {
      pc += P[i];
      qc += Q[i];
    }
    pc /= static_cast<double>(P.size());
    qc /= static_cast<double>(P.size());
    Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
    for (std::size_t i = 0; i < P.size(); ++i) H += (P[i] - pc) * (Q[i] - qc).transpose();
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
    // Points on a line (a single suture edge) leave the rotation about that line undetermined.
    if (!(svd.singularValues()[1] > 1e-6 * svd.singularValues()[0])) continue;
    Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
    D(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1 : 1;
    const Eigen::Matrix3d R = svd.matrixV() * D * svd.matrixU().transpose();
    const Eigen::AngleAxisd aa(R);
    rotations_deg_[static_cast<std::size_t>(f)] = aa.angle() * 180 / std::numbers::pi;
    if (!(aa.angle() * 180 / std::numbers::pi >= kMinRotationDeg)) continue;
    // The screw axis: x -> R x + t with t = qc - R pc; its points c solve (I - R) c = t_perp.
    // The solution nearest the flap's centroid.
    Motion& mo = motions_[static_cast<std::size_t>(f)];
    mo.axis = aa.axis().normalized();
    mo.angle = aa.angle();
    const Eigen::Vector3d t = qc - R * pc;
    const Eigen::Vector3d t_perp = t - mo.axis.dot(t) * mo.axis;
    const Eigen::Matrix3d A = Eigen::Matrix3d::Identity() - R;
    Eigen::CompleteOrthogonalDecomposition<Eigen::Matrix3d> cod;
    cod.setThreshold(1e-8);
    cod.compute(A);
    mo.centre = pc + cod.solve(Eigen::Vector3d(t_perp - A * pc));
  }

  // A flap swings about its base, which stays attached: a node's arc is scaled by its distance
  // from the base (the flap's nodes shared with the surrounding skin) relative to the farthest
  // node (the tip). Without the scaling, the nodes of an edge sutured to the other flap, which
  // run from the base out to the tip, would all be swung as far as the tip.
  swing_.assign(static_cast<std::size_t>(n), 0.0);
  for (int f = 0; f < n_flaps; ++f) {
    if (!(motions_[static_cast<std::size_t>(f)].angle > 0)) continue;
    std::vector<char> in_flap(static_cast<std::size_t>(n), 0);
    for (int e : mesh.flaps[static_cast<std::size_t>(f)])
      for (int a = 0; a < mesh.elements[static_cast<std::size_t>(e)].n_nodes(); ++a)
        in_flap[static_cast<std::size_t>(mesh.elements[static_cast<std::size_t>(e)].nodes[a])] = 1;
    std::vector<int> base, own;
    for (int i = 0; i < n; ++i)
      if (in_flap[static_cast<std::size_t>(i)]) (node_flap_[static_cast<std::size_t>(i)] == f ? own : base).push_back(i);
    if (base.empty()) {  // cut free all round (an island): the whole flap swings
      for (int i : own) swing_[static_cast<std::size_t>(i)] = 1;
      continue;
    }
    double far = 0;
    for (int i : own) {
      double d = INFINITY;
      for (int b : base) d = std::min(d, (mesh.nodes.row(i) - mesh.nodes.row(b)).norm());
      swing_[static_cast<std::size_t>(i)] = d;
      far = std::max(far, d);
    }
    for (int i : own) swing_[static_cast<std::size_t>(i)] = far > 0 ? swing_[static_cast<std::size_t>(i)] / far : 0.0;
  }

  // The offset dofs whose path bends: members of a group with a node on a turned flap.
  for (const auto& members : map.groups) {
    bool turned = false;
    for (int m : members)
      if (const int f = node_flap_[static_cast<std::size_t>(m)]; f >= 0 && motions_[static_cast<std::size_t>(f)].angle > 0)
        turned = true;
    if (!turned) continue;
    for (int m : members)
      for (int c = 0; c < 3; ++c) {
        const int d = 3 * m + c;
        moved_.emplace_back(d, map.eq[static_cast<std::size_t>(d)] >= 0 ? members.front() : -1);
      }
  }
}

Eigen::Vector3d ClosingPath::arc(const Motion& m, int n, double lambda) const {
  const Eigen::Vector3d v = mesh_.nodes.row(n).transpose() - m.centre;
  return turn_minus_identity(m.axis, lambda * m.angle, v) - lambda * turn_minus_identity(m.axis, m.angle, v);
}

Eigen::VectorXd ClosingPath::at(double lambda) const {
  Eigen::VectorXd u = lambda * map_.g;
  if (lambda == 0 || lambda == 1) return u;
  auto arc_of = [&](int node) -> Eigen::Vector3d {
    const int f = node_flap_[static_cast<std::size_t>(node)];
    if (f < 0 || !(motions_[static_cast<std::size_t>(f)].angle > 0)) return Eigen::Vector3d::Zero();
    return swing_[static_cast<std::size_t>(node)] * arc(motions_[static_cast<std::size_t>(f)], node, lambda);
  };
  // A free group: u_n - u_master = lambda (X_master - X_n) + D_n - D_master. A prescribed one
  // meets at its fixed point p: u_n = lambda (p - X_n) + D_n.
  for (const auto& [d, reference] : moved_) {
    const int node = d / 3, c = d % 3;
    if (node == reference) continue;
    u[d] += arc_of(node)[c] - (reference >= 0 ? arc_of(reference)[c] : 0.0);
  }
  return u;
}

}  // namespace caps::fem::detail

#include "caps/fem/tie.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <unordered_map>

#include "caps/core/error.hpp"
#include "caps/fem/elements.hpp"

namespace caps::fem {
namespace {

// Weights below this are dropped from a tie (the opposite face's nodes of a point on a face).
constexpr double kDropWeight = 1e-12;
// Quadratic elements may bulge beyond their nodes' bounding box: candidates are searched in the
// box grown by this fraction of its largest extent (and by the tolerance).
constexpr double kBoxMargin = 0.25;
// Boxes wider than this many grid cells are not put in the grid (see `big`).
constexpr double kMaxCellsPerBox = 16;

// The reference domain of an element type as half-spaces a . xi <= b: the facets of the convex
// hull of its natural nodes (a hexahedron's six faces, a wedge's five, a tetrahedron's four), so
// every element type that shape_functions() knows is searched the same way.
struct ReferenceDomain {
  std::vector<Eigen::Vector3d> a;
  std::vector<double> b;
  Eigen::Vector3d centre;
};

ReferenceDomain reference_domain(ElementType type) {
  const Eigen::MatrixX3d P = natural_nodes(type);
  const Eigen::Index n = P.rows();
  ReferenceDomain d;
  d.centre = P.colwise().mean().transpose();
  for (Eigen::Index i = 0; i < n; ++i)
    for (Eigen::Index j = i + 1; j < n; ++j)
      for (Eigen::Index k = j + 1; k < n; ++k) {
        Eigen::Vector3d normal = (P.row(j) - P.row(i)).cross(P.row(k) - P.row(i)).transpose();
        if (normal.norm() < 1e-9) continue;
        normal.normalize();
        double b = normal.dot(P.row(i).transpose());
        if (normal.dot(d.centre) > b) {
          normal = -normal;
          b = -b;
        }
        bool facet = true;
        for (Eigen::Index l = 0; l < n && facet; ++l) facet = normal.dot(P.row(l).transpose()) <= b + 1e-9;
        if (!facet) continue;
        bool known = false;
        for (std::size_t f = 0; f < d.a.size() && !known; ++f)
          known = (d.a[f] - normal).norm() < 1e-9 && std::abs(d.b[f] - b) < 1e-9;
        if (!known) {
          d.a.push_back(normal);
          d.b.push_back(b);
        }
      }
  return d;
}

// The point of element X (#n×3) nearest to p: min 1/2 |x(xi) - p|^2 over the reference domain,
// by Gauss-Newton with an active set of the domain's faces (Nocedal & Wright 2006, sec. 16.5):
// each step solves the linearised problem on the faces held active, is cut at the first face
// it crosses (which joins the set), and a face whose multiplier pulls inwards leaves it. Inside
// the element this is Newton's inversion of the map x(xi) = p.
struct Closest {
  Eigen::Vector3d xi;
  double distance = INFINITY;
};

Closest closest_point(ElementType type, const ReferenceDomain& dom, const Eigen::MatrixX3d& X,
                      const Eigen::Vector3d& p) {
  Eigen::VectorXd N;
  Eigen::MatrixX3d dN;
  Eigen::Vector3d xi = dom.centre;
  std::vector<int> active;
  auto residual = [&](const Eigen::Vector3d& at, Eigen::Matrix3d* J) {
    shape_functions(type, at, N, dN);
    if (J) *J = X.transpose() * dN;  // dx/dxi
    return Eigen::Vector3d(p - X.transpose() * N);
  };
  Eigen::Matrix3d J;
  Eigen::Vector3d r = residual(xi, &J);
  for (int it = 0; it < 100; ++it) {
    // Null space of the active faces' normals.
    Eigen::Matrix3d Z = Eigen::Matrix3d::Identity();
    int n_free = 3;
    if (!active.empty()) {
      Eigen::MatrixXd A(static_cast<Eigen::Index>(active.size()), 3);
      for (std::size_t i = 0; i < active.size(); ++i) A.row(static_cast<Eigen::Index>(i)) = dom.a[active[i]].transpose();
      Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullV);
      svd.setThreshold(1e-9);
      const int rank = static_cast<int>(svd.rank());
      n_free = 3 - rank;
      Z = svd.matrixV();
      Z.leftCols(n_free) = svd.matrixV().rightCols(n_free).eval();
    }
    Eigen::Vector3d d = Eigen::Vector3d::Zero();
    if (n_free > 0) {
      const Eigen::MatrixXd JZ = J * Z.leftCols(n_free);
      const Eigen::VectorXd y = (JZ.transpose() * JZ).ldlt().solve(JZ.transpose() * r);
      d = Z.leftCols(n_free) * y;
    }
    if (!d.allFinite()) break;
    if (d.norm() < 1e-13) {
      // Stationary on the active faces: a face whose multiplier is negative leaves the set.
      if (active.empty()) break;
      const Eigen::Vector3d g = -J.transpose() * r;  // gradient of 1/2 |r|^2
      Eigen::MatrixXd At(3, static_cast<Eigen::Index>(active.size()));
      for (std::size_t i = 0; i < active.size(); ++i) At.col(static_cast<Eigen::Index>(i)) = dom.a[active[i]];
      const Eigen::VectorXd mu = At.completeOrthogonalDecomposition().solve(-g);
      Eigen::Index worst;
      if (mu.minCoeff(&worst) >= -1e-14 * (1 + g.norm())) break;
      active.erase(active.begin() + worst);
      continue;
    }
    // Cut at the first inactive face the step crosses.
    double alpha = 1;
    int blocking = -1;
    for (std::size_t f = 0; f < dom.a.size(); ++f) {
      if (std::find(active.begin(), active.end(), static_cast<int>(f)) != active.end()) continue;
      const double ad = dom.a[f].dot(d);
      if (ad <= 1e-15) continue;
      const double t = (dom.b[f] - dom.a[f].dot(xi)) / ad;
      if (t < alpha) {
        alpha = std::max(t, 0.0);
        blocking = static_cast<int>(f);
      }
    }
    // Backtrack while the distance grows (a strongly curved element far from p).
    const double f0 = r.squaredNorm();
    Eigen::Vector3d xi_new = xi + alpha * d, r_new = residual(xi_new, nullptr);
    for (int ls = 0; ls < 30 && r_new.squaredNorm() > f0 * (1 + 1e-12) + 1e-30; ++ls) {
      alpha *= 0.5;
      blocking = -1;
      xi_new = xi + alpha * d;
      r_new = residual(xi_new, nullptr);
    }
    xi = xi_new;
    if (blocking >= 0) active.push_back(blocking);
    r = residual(xi, &J);
    if (alpha * d.norm() < 1e-14 && blocking < 0) break;
  }
  return {xi, r.norm()};
}

struct Box {
  Eigen::Vector3d lo, hi;
  double distance(const Eigen::Vector3d& p) const {
    return (p - p.cwiseMax(lo).cwiseMin(hi)).norm();
  }
};

}  // namespace

TieSearchResult tie_nodes(const Mesh& mesh, const std::vector<int>& slaves,
                          const std::vector<int>& master_elements, double tolerance_mm) {
  if (!(tolerance_mm >= 0) || !std::isfinite(tolerance_mm))
    throw InvalidInput(cat("tie: the tolerance ", tolerance_mm, " mm must be finite and >= 0"));
  const Eigen::Index n_nodes = mesh.n_nodes();
  const long n_elements = static_cast<long>(mesh.elements.size());
  std::vector<char> seen(static_cast<std::size_t>(n_nodes), 0);
  for (int s : slaves) {
    if (s < 0 || s >= n_nodes)
      throw InvalidInput(cat("tie: slave node ", s, " is out of range (node ids run 0..", n_nodes - 1, ")"));
    if (seen[s]++) throw InvalidInput(cat("tie: slave node ", s, " is given twice; tie it once"));
  }
  for (int e : master_elements)
    if (e < 0 || e >= n_elements)
      throw InvalidInput(cat("tie: master element ", e, " is out of range (element ids run 0..",
                             n_elements - 1, ")"));

  // The master elements' grown boxes, in a uniform grid of cells the size of a median element.
  std::vector<Box> boxes(master_elements.size());
  std::vector<double> extents;
  for (std::size_t i = 0; i < master_elements.size(); ++i) {
    const Eigen::MatrixX3d X = element_coordinates(mesh, master_elements[i]);
    Box b{X.colwise().minCoeff().transpose(), X.colwise().maxCoeff().transpose()};
    const double grow = kBoxMargin * (b.hi - b.lo).maxCoeff() + tolerance_mm;
    b.lo.array() -= grow;
    b.hi.array() += grow;
    boxes[i] = b;
    extents.push_back((b.hi - b.lo).maxCoeff());
  }
  double cell = 1;
  if (!extents.empty()) {
    std::nth_element(extents.begin(), extents.begin() + static_cast<long>(extents.size() / 2), extents.end());
    cell = std::max(extents[extents.size() / 2], 1e-9);
  }
  auto cell_of = [&](double v) { return static_cast<long>(std::floor(v / cell)); };
  auto key = [](long i, long j, long k) {
    return (static_cast<std::uint64_t>(i & 0x1fffff) << 42) | (static_cast<std::uint64_t>(j & 0x1fffff) << 21) |
           static_cast<std::uint64_t>(k & 0x1fffff);
  };
  std::unordered_map<std::uint64_t, std::vector<int>> grid;
  std::vector<int> big;  // boxes spanning many cells (a huge element among small ones): tried for every slave
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    const Box& b = boxes[i];
    if ((b.hi - b.lo).maxCoeff() > kMaxCellsPerBox * cell) {
      big.push_back(static_cast<int>(i));
      continue;
    }
    for (long x = cell_of(b.lo.x()); x <= cell_of(b.hi.x()); ++x)
      for (long y = cell_of(b.lo.y()); y <= cell_of(b.hi.y()); ++y)
        for (long z = cell_of(b.lo.z()); z <= cell_of(b.hi.z()); ++z)
          grid[key(x, y, z)].push_back(static_cast<int>(i));
  }

  std::unordered_map<int, ReferenceDomain> domains;
  for (int e : master_elements) {
    const ElementType t = mesh.elements[e].type;
    if (!domains.count(static_cast<int>(t))) domains.emplace(static_cast<int>(t), reference_domain(t));
  }
  const auto uses = [&](int e, int node) {
    const Element& el = mesh.elements[e];
    return std::find(el.nodes.begin(), el.nodes.begin() + el.n_nodes(), node) != el.nodes.begin() + el.n_nodes();
  };
  const auto try_element = [&](std::size_t i, const Eigen::Vector3d& p) {
    const int e = master_elements[i];
    const Element& el = mesh.elements[e];
    return closest_point(el.type, domains.at(static_cast<int>(el.type)), element_coordinates(mesh, e), p);
  };

  TieSearchResult out;
  for (int s : slaves) {
    const Eigen::Vector3d p = mesh.nodes.row(s).transpose();
    Closest best;
    int best_i = -1;
    const auto consider = [&](std::size_t i) {
      if (uses(master_elements[i], s)) return;
      const Closest c = try_element(i, p);
      // Equal distances (a point on a face two masters share) keep the first element.
      if (c.distance < best.distance - 1e-12) {
        best = c;
        best_i = static_cast<int>(i);
      }
    };
    const auto found = grid.find(key(cell_of(p.x()), cell_of(p.y()), cell_of(p.z())));
    if (found != grid.end())
      for (int i : found->second)
        if (boxes[i].distance(p) == 0) consider(static_cast<std::size_t>(i));
    for (int i : big)
      if (boxes[i].distance(p) == 0) consider(static_cast<std::size_t>(i));
    if (best_i < 0 || best.distance > tolerance_mm) {
      // The nearest master element, exactly: elements in order of their box's distance until
      // the next box is farther than the best point found.
      std::vector<std::pair<double, std::size_t>> order;
      for (std::size_t i = 0; i < boxes.size(); ++i) order.emplace_back(boxes[i].distance(p), i);
      std::sort(order.begin(), order.end());
      for (const auto& [box_distance, i] : order) {
        if (box_distance > best.distance) break;
        consider(i);
      }
    }
    if (best_i < 0 || best.distance > tolerance_mm) {
      out.unmatched.push_back(s);
      out.unmatched_distance_mm.push_back(best.distance);
      continue;
    }
    const int e = master_elements[best_i];
    const Element& el = mesh.elements[e];
    Eigen::VectorXd N;
    Eigen::MatrixX3d dN;
    shape_functions(el.type, best.xi, N, dN);
    TiedNode t;
    t.node = s;
    for (int a = 0; a < el.n_nodes(); ++a)
      if (std::abs(N[a]) >= kDropWeight) {
        t.masters.push_back(el.nodes[a]);
        t.weights.push_back(N[a]);
      }
    const double sum = std::accumulate(t.weights.begin(), t.weights.end(), 0.0);
    for (double& w : t.weights) w /= sum;
    out.ties.push_back(std::move(t));
    out.master_element.push_back(e);
    out.natural.push_back(best.xi);
    out.distance_mm.push_back(best.distance);
  }
  return out;
}

}  // namespace caps::fem

#include "caps/fem/tie.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
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

struct Closest {
  Eigen::Vector3d xi = Eigen::Vector3d::Zero();
  double distance = INFINITY;
};

// The point of triangle a b c nearest to p, as (v, w): a + v (b - a) + w (c - a) (Ericson 2005,
// "Real-Time Collision Detection", sec. 5.1.5: Voronoi regions of the vertices, edges and face).
Eigen::Vector2d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                    const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {0, 0};
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return {d1 / (d1 - d3), 0};
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return {0, d2 / (d2 - d6)};
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {1 - t, t};
  }
  const double denom = 1 / (va + vb + vc);
  return {vb * denom, vc * denom};
}

// A Tet10 whose mid-edge nodes sit at their edges' midpoints (the tissue model's, made from
// linear tets) is the affine image of the reference tetrahedron, x = X0 + J xi: its nearest point
// is found in closed form, the point itself when inside, else the nearest point of its nearest
// face. Other elements (curved Tet10, Hex20, Wedge15) return false and are searched iteratively.
bool closest_point_affine_tet(ElementType type, const Eigen::MatrixX3d& X, const Eigen::Vector3d& p,
                              Closest& out) {
  if (type != ElementType::Tet10) return false;
  static constexpr int kEdges[6][2] = {{0, 1}, {1, 2}, {2, 0}, {0, 3}, {1, 3}, {2, 3}};
  Eigen::Matrix3d J;
  for (int k = 0; k < 3; ++k) J.col(k) = (X.row(k + 1) - X.row(0)).transpose();
  const double size = J.cwiseAbs().maxCoeff();
  for (int k = 0; k < 6; ++k)
    if ((X.row(4 + k) - 0.5 * (X.row(kEdges[k][0]) + X.row(kEdges[k][1]))).cwiseAbs().maxCoeff() > 1e-9 * size)
      return false;
  const double det = J.determinant();
  if (!(std::abs(det) > 1e-12 * size * size * size)) return false;
  const Eigen::Vector3d x0 = X.row(0).transpose();
  const Eigen::Vector3d xi = J.inverse() * (p - x0);
  if (xi.minCoeff() >= 0 && xi.sum() <= 1) {
    out.xi = xi;
    out.distance = (x0 + J * xi - p).norm();
    return true;
  }
  // The four faces as (corner, corner, corner) with the natural coordinates of each corner.
  static constexpr int kFaces[4][3] = {{0, 1, 2}, {0, 1, 3}, {1, 2, 3}, {0, 2, 3}};
  const Eigen::Vector3d corner_xi[4] = {Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX(),
                                        Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ()};
  out.distance = INFINITY;
  for (const auto& f : kFaces) {
    const Eigen::Vector3d a = X.row(f[0]).transpose(), b = X.row(f[1]).transpose(), c = X.row(f[2]).transpose();
    const Eigen::Vector2d vw = closest_on_triangle(p, a, b, c);
    const double d = (a + vw[0] * (b - a) + vw[1] * (c - a) - p).norm();
    if (d < out.distance) {
      out.distance = d;
      out.xi = corner_xi[f[0]] + vw[0] * (corner_xi[f[1]] - corner_xi[f[0]]) +
               vw[1] * (corner_xi[f[2]] - corner_xi[f[0]]);
    }
  }
  return true;
}

// The point of element X (#n×3) nearest to p: min 1/2 |x(xi) - p|^2 over the reference domain,
// by Gauss-Newton with an active set of the domain's faces (Nocedal & Wright 2006, sec. 16.5):
// each step solves the linearised problem on the faces held active, is cut at the first face
// it crosses (which joins the set), and a face whose multiplier pulls inwards leaves it. Inside
// the element this is Newton's inversion of the map x(xi) = p.
Closest closest_point(ElementType type, const ReferenceDomain& dom, const Eigen::MatrixX3d& X,
                      const Eigen::Vector3d& p) {
  if (Closest c; closest_point_affine_tet(type, X, p, c)) return c;
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

// The mortar rows (tie.hpp): for every slave on a slave face (a face of an element outside the
// masters whose nodes are all slaves), int_G N_s (u_slave - u_master) dA = 0 over its faces,
// integrated on n x n sub-cells of each face with 3 x 3 Gauss points, each point's master value
// taken at its nearest master point. A face with a point farther than the tolerance is left out.
template <class Locate>
void mortar_rows(const Mesh& mesh, const std::vector<int>& slaves, const std::vector<int>& master_elements,
                 double tolerance_mm, double master_size, const Locate& locate,
                 const std::unordered_map<int, std::size_t>& tie_of, TieSearchResult& out) {
  const Eigen::Index n_nodes = mesh.n_nodes();
  std::vector<char> is_slave(static_cast<std::size_t>(n_nodes), 0), is_master(mesh.elements.size(), 0);
  for (int s : slaves) is_slave[s] = 1;
  for (int e : master_elements) is_master[e] = 1;
  std::unordered_map<int, ReferenceDomain> domains;
  std::unordered_map<int, std::unordered_map<int, double>> M, D;  // slave -> slave' / master -> value
  const double gauss[3] = {0.5 - std::sqrt(0.15), 0.5, 0.5 + std::sqrt(0.15)};
  const double gw[3] = {5.0 / 18, 8.0 / 18, 5.0 / 18};
  Eigen::VectorXd N, Nm;
  Eigen::MatrixX3d dN, dNm;
  for (std::size_t e = 0; e < mesh.elements.size(); ++e) {
    if (is_master[e]) continue;
    const Element& el = mesh.elements[e];
    bool touches = false;
    for (int a = 0; a < el.n_nodes() && !touches; ++a) touches = is_slave[el.nodes[a]];
    if (!touches) continue;
    if (!domains.count(static_cast<int>(el.type))) domains.emplace(static_cast<int>(el.type), reference_domain(el.type));
    const ReferenceDomain& dom = domains.at(static_cast<int>(el.type));
    const Eigen::MatrixX3d P = natural_nodes(el.type);
    const Eigen::MatrixX3d X = element_coordinates(mesh, static_cast<int>(e));
    for (std::size_t f = 0; f < dom.a.size(); ++f) {
      std::vector<int> face;  // local nodes on the facet
      bool all_slaves = true;
      for (int a = 0; a < el.n_nodes(); ++a)
        if (std::abs(dom.a[f].dot(P.row(a).transpose()) - dom.b[f]) < 1e-9) {
          face.push_back(a);
          all_slaves = all_slaves && is_slave[el.nodes[a]];
        }
      if (!all_slaves || face.size() < 3) continue;
      // The facet's corners (its nodes that are no midpoint of two others), in order around it.
      std::vector<Eigen::Vector3d> corners;
      for (int a : face) {
        bool mid = false;
        for (int b : face)
          for (int c : face)
            if (b < c && a != b && a != c && (P.row(a) - 0.5 * (P.row(b) + P.row(c))).norm() < 1e-9) mid = true;
        if (!mid) corners.push_back(P.row(a).transpose());
      }
      if (corners.size() != 3 && corners.size() != 4) continue;
      Eigen::Vector3d centre = Eigen::Vector3d::Zero();
      for (const auto& c : corners) centre += c / static_cast<double>(corners.size());
      const Eigen::Vector3d u0 = (corners[0] - centre).normalized(), v0 = dom.a[f].cross(u0);
      std::sort(corners.begin(), corners.end(), [&](const Eigen::Vector3d& p, const Eigen::Vector3d& q) {
        return std::atan2((p - centre).dot(v0), (p - centre).dot(u0)) <
               std::atan2((q - centre).dot(v0), (q - centre).dot(u0));
      });
      const bool quad = corners.size() == 4;
      double face_size = 0;
      for (int a : face)
        for (int b : face) face_size = std::max(face_size, (X.row(a) - X.row(b)).norm());
      const int n = std::clamp(static_cast<int>(std::ceil(4 * face_size / master_size)), 4, 16);
      std::unordered_map<int, std::unordered_map<int, double>> Mf, Df;
      bool matched = true;
      for (int ci = 0; ci < n && matched; ++ci)
        for (int cj = 0; cj < n && matched; ++cj)
          for (int gi = 0; gi < 3 && matched; ++gi)
            for (int gj = 0; gj < 3 && matched; ++gj) {
              const double s = (ci + gauss[gi]) / n, t = (cj + gauss[gj]) / n, w = gw[gi] * gw[gj] / (n * n);
              Eigen::Vector3d xi, xs, xt;
              if (quad) {
                xi = (1 - s) * (1 - t) * corners[0] + s * (1 - t) * corners[1] + s * t * corners[2] + (1 - s) * t * corners[3];
                xs = (1 - t) * (corners[1] - corners[0]) + t * (corners[2] - corners[3]);
                xt = (1 - s) * (corners[3] - corners[0]) + s * (corners[2] - corners[1]);
              } else {  // the triangle as a collapsed square (Duffy): (s, t (1 - s))
                xi = corners[0] + s * (corners[1] - corners[0]) + t * (1 - s) * (corners[2] - corners[0]);
                xs = (corners[1] - corners[0]) - t * (corners[2] - corners[0]);
                xt = (1 - s) * (corners[2] - corners[0]);
              }
              shape_functions(el.type, xi, N, dN);
              const Eigen::Matrix3d J = X.transpose() * dN;
              const double dA = (J * xs).cross(J * xt).norm() * w;
              const Eigen::Vector3d x = X.transpose() * N;
              Closest c;
              const int mi = locate(x, -1, c);
              if (mi < 0 || c.distance > tolerance_mm) {
                matched = false;
                break;
              }
              const Element& mel = mesh.elements[master_elements[mi]];
              shape_functions(mel.type, c.xi, Nm, dNm);
              for (int a : face) {
                if (N[a] == 0) continue;
                for (int b : face) Mf[el.nodes[a]][el.nodes[b]] += dA * N[a] * N[b];
                for (int m = 0; m < mel.n_nodes(); ++m) Df[el.nodes[a]][mel.nodes[m]] += dA * N[a] * Nm[m];
              }
            }
      if (!matched) continue;
      for (auto& [row, entries] : Mf)
        for (auto& [col, v] : entries) M[row][col] += v;
      for (auto& [row, entries] : Df)
        for (auto& [col, v] : entries) D[row][col] += v;
    }
  }
  // Each slave's row, scaled so that its own coefficient is 1: u_s = sum_m (D_sm / M_ss) u_m -
  // sum_{s' != s} (M_ss' / M_ss) u_s'; the weights sum to 1 (sum_m N_m = 1 at every point).
  for (const auto& [s, row] : M) {
    const auto found = tie_of.find(s);
    const auto diagonal = row.find(s);
    if (found == tie_of.end() || diagonal == row.end() || !(diagonal->second > 0)) continue;
    const double mss = diagonal->second;
    std::map<int, double> w;
    for (const auto& [col, v] : row)
      if (col != s) w[col] -= v / mss;
    for (const auto& [col, v] : D[s]) w[col] += v / mss;
    TiedNode t;
    t.node = s;
    double sum = 0;
    for (const auto& [node, weight] : w)
      if (std::abs(weight) >= kDropWeight && node != s) {
        t.masters.push_back(node);
        t.weights.push_back(weight);
        sum += weight;
      }
    for (double& weight : t.weights) weight /= sum;
    out.ties[found->second] = std::move(t);
    ++out.n_mortar;
  }
}

}  // namespace

const char* tie_method_name(TieMethod method) {
  return method == TieMethod::Mortar ? "mortar" : "node-to-surface";
}

TieMethod parse_tie_method(const std::string& name) {
  if (name == "mortar") return TieMethod::Mortar;
  if (name == "node-to-surface") return TieMethod::NodeToSurface;
  throw InvalidInput(cat("tie '", name, "' is unknown; use mortar or node-to-surface"));
}

TieSearchResult tie_nodes(const Mesh& mesh, const std::vector<int>& slaves,
                          const std::vector<int>& master_elements, double tolerance_mm,
                          TieMethod method, Reporter* reporter) {
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

  // The nearest point of the master elements to p (not of an element using node `exclude`):
  // the grid's candidates first, then, if none is within the tolerance, every element in order
  // of its box's distance until the next box is farther than the best point found.
  const auto locate = [&](const Eigen::Vector3d& p, int exclude, Closest& best) {
    if (reporter) reporter->check_cancelled();
    best = Closest{};
    int best_i = -1;
    const auto consider = [&](std::size_t i) {
      if (exclude >= 0 && uses(master_elements[i], exclude)) return;
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
      std::vector<std::pair<double, std::size_t>> order;
      for (std::size_t i = 0; i < boxes.size(); ++i) order.emplace_back(boxes[i].distance(p), i);
      std::sort(order.begin(), order.end());
      for (const auto& [box_distance, i] : order) {
        if (box_distance > best.distance) break;
        consider(i);
      }
    }
    return best_i;
  };

  TieSearchResult out;
  std::unordered_map<int, std::size_t> tie_of;  // slave -> its entry in out.ties
  for (int s : slaves) {
    const Eigen::Vector3d p = mesh.nodes.row(s).transpose();
    Closest best;
    const int best_i = locate(p, s, best);
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
    tie_of[s] = out.ties.size();
    out.ties.push_back(std::move(t));
    out.master_element.push_back(e);
    out.natural.push_back(best.xi);
    out.distance_mm.push_back(best.distance);
  }
  if (method == TieMethod::Mortar) mortar_rows(mesh, slaves, master_elements, tolerance_mm, cell, locate, tie_of, out);
  return out;
}

}  // namespace caps::fem

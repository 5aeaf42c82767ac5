#include "caps/mesher/surface_mesher.hpp"

#include "caps/core/error.hpp"
#include "caps/surface/patient_model.hpp"
#include "stage1_region.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <numeric>

namespace caps::mesher {

using namespace caps::fem;
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

using Vec2 = Eigen::Vector2d;

double cross2(const Vec2& a, const Vec2& b) { return a.x() * b.y() - a.y() * b.x(); }

/// Signed turning angle at b (radians, (-pi, pi]); an exact reversal (a slit's end, where the
/// hole angle is 0) is +pi: seen from the hole, a slit's end is always convex.
double turning(const Vec2& a, const Vec2& b, const Vec2& c) {
  const Vec2 d1 = b - a, d2 = c - b;
  const double cr = cross2(d1, d2), dt = d1.dot(d2);
  if (std::abs(cr) <= 1e-12 * d1.norm() * d2.norm() && dt < 0) return kPi;
  return std::atan2(cr, dt);
}

/// Outward (tissue-side) unit normal of a border edge a -> b: the hole is on the left.
Vec2 outward(const Vec2& a, const Vec2& b) {
  const Vec2 d = (b - a).normalized();
  return {d.y(), -d.x()};
}

Vec2 rotate(const Vec2& v, double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  return {c * v.x() - s * v.y(), s * v.x() + c * v.y()};
}

double polygon_area(const std::vector<Vec2>& P, const std::vector<int>& ids) {
  double a = 0;
  for (std::size_t i = 0; i < ids.size(); ++i)
    a += cross2(P[ids[i]], P[ids[(i + 1) % ids.size()]]);
  return 0.5 * a;
}

bool point_in_triangle(const Vec2& p, const Vec2& a, const Vec2& b, const Vec2& c) {
  const double tol = 1e-9 * ((b - a).norm() + (c - b).norm());
  return cross2(b - a, p - a) > tol && cross2(c - b, p - b) > tol && cross2(a - c, p - c) > tol;
}

bool segments_cross(const Vec2& p1, const Vec2& p2, const Vec2& q1, const Vec2& q2) {
  const double d1 = cross2(p2 - p1, q1 - p1), d2 = cross2(p2 - p1, q2 - p1);
  const double d3 = cross2(q2 - q1, p1 - q1), d4 = cross2(q2 - q1, p2 - q1);
  return ((d1 > 0) != (d2 > 0)) && ((d3 > 0) != (d4 > 0)) && d1 != 0 && d2 != 0 && d3 != 0 &&
         d4 != 0;
}

struct Builder {
  std::vector<Vec2> P;
  SurfaceMesh out;
  bool mirrored = false;

  int add_vertex(Vec2 p) {
    P.push_back(p);
    return static_cast<int>(P.size()) - 1;
  }
  Eigen::Vector2d theta_z(const Vec2& p) const {
    const double x = mirrored ? -p.x() : p.x();
    return {out.theta_c_deg + x / out.ref_radius_mm / kDeg, out.z_c_mm + p.y()};
  }
  // The first refusal met (a polygon that folds, a layer that overlaps itself): the stage that
  // met it finishes and the mesher stops after it.
  std::optional<MeshRefusal> refusal;
  void refuse(MeshRefusal::Kind kind, const Eigen::Vector2d& tz, std::string message) {
    if (!refusal) refusal = MeshRefusal{kind, tz.x(), tz.y(), std::move(message)};
  }

  void add_polygon(std::vector<int> ids, int stage, int layer, int expanded) {
    if (!(polygon_area(P, ids) > 0)) {
      Vec2 c = Vec2::Zero();
      for (int id : ids) c += P[id];
      const Eigen::Vector2d tz = theta_z(c / ids.size());
      refuse(MeshRefusal::Kind::Folded, tz,
             cat("surface mesh: layer ", layer, " folds over near theta ",
                 std::round(tz.x() * 10) / 10, " deg, z ",
                 std::round(tz.y() * 10) / 10, " mm (an element has no positive "
                 "area); use a smaller {mesh_size} or check the wound border there"));
    }
    out.polygons.push_back(std::move(ids));
    out.polygon_stage.push_back(stage);
    out.polygon_layer.push_back(layer);
    out.polygon_expanded.push_back(expanded);
  }
  /// Refuses the mesh (Folded) if the closed polygon `border` crosses itself.
  void check_simple(const std::vector<int>& border, int layer) {
    if (refusal) return;
    const std::size_t m = border.size();
    for (std::size_t i = 0; i < m; ++i)
      for (std::size_t j = i + 2; j < m; ++j) {
        if (i == 0 && j == m - 1) continue;
        const Vec2 &p1 = P[border[i]], &p2 = P[border[(i + 1) % m]];
        const Vec2 &q1 = P[border[j]], &q2 = P[border[(j + 1) % m]];
        if (segments_cross(p1, p2, q1, q2)) {
          const Eigen::Vector2d tz = theta_z(0.5 * (p1 + p2));
          refuse(MeshRefusal::Kind::Folded, tz,
                 cat("surface mesh: layer ", layer, " overlaps itself near theta ",
                     std::round(tz.x() * 10) / 10, " deg, z ",
                     std::round(tz.y() * 10) / 10, " mm; use a smaller "
                     "{mesh_size}, a smaller {extent}, or a wound border without "
                     "tight folds"));
          return;
        }
      }
  }
};

double median_edge(const std::vector<Vec2>& P, const std::vector<int>& border) {
  std::vector<double> len;
  for (std::size_t i = 0; i < border.size(); ++i)
    len.push_back((P[border[(i + 1) % border.size()]] - P[border[i]]).norm());
  std::nth_element(len.begin(), len.begin() + len.size() / 2, len.end());
  return len[len.size() / 2];
}

double min_corner_deg(const std::vector<Vec2>& P, const std::vector<int>& poly) {
  double m = 180;
  const std::size_t n = poly.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Vec2 u = P[poly[(i + n - 1) % n]] - P[poly[i]], v = P[poly[(i + 1) % n]] - P[poly[i]];
    m = std::min(m, std::atan2(std::abs(cross2(u, v)), u.dot(v)) / kDeg);
  }
  return m;
}

/// Re-triangulates each edge-connected region of stage-1 triangles (the only polygons so far)
/// whose smallest corner is below `min_angle_deg`. Stage 1 fills a large flap with a ladder of
/// thin triangles across it (3.9 deg on the V-Y template's 50 deg V of 20 mm arms); a constrained
/// Delaunay refinement of the same region gives well-shaped triangles with interior points. The
/// border chains are kept edge for edge; the region's front edges (the diagonals stage 1 leaves
/// for stage 2, up to the whole base of a flap) are split into pieces of about `size_mm`, since
/// no triangle on a long unsplit edge between short border edges can be well shaped, and the
/// pieces join the front. A rebuild that is not better keeps stage 1's triangles.
void rebuild_stage1(Builder& B, std::vector<int>& front, double min_angle_deg, double size_mm) {
  auto& polys = B.out.polygons;
  const int m = static_cast<int>(polys.size());
  std::vector<int> parent(m);
  std::iota(parent.begin(), parent.end(), 0);
  auto root = [&](int t) {
    while (parent[t] != t) t = parent[t] = parent[parent[t]];
    return t;
  };
  std::map<std::pair<int, int>, int> directed;  // edge a -> b of triangle t
  for (int t = 0; t < m; ++t)
    for (int i = 0; i < 3; ++i) directed[{polys[t][i], polys[t][(i + 1) % 3]}] = t;
  for (const auto& [e, t] : directed) {
    const auto twin = directed.find({e.second, e.first});
    if (twin != directed.end()) parent[root(t)] = root(twin->second);
  }
  std::map<int, std::vector<int>> regions;
  for (int t = 0; t < m; ++t) regions[root(t)].push_back(t);
  // Stage 1's front edges run the same way as the region's boundary (a triangle (c, b, a) leaves
  // the front edge a -> c).
  std::map<std::pair<int, int>, std::vector<int>> front_split;
  for (std::size_t i = 0; i < front.size(); ++i)
    front_split[{front[i], front[(i + 1) % front.size()]}] = {};

  std::vector<std::vector<int>> rebuilt;
  for (const auto& region : regions) {
    const std::vector<int>& tris = region.second;  // clang 14 cannot capture a structured binding
    double worst = 180;
    for (int t : tris) worst = std::min(worst, min_corner_deg(B.P, polys[t]));
    auto keep = [&] {
      for (int t : tris) rebuilt.push_back(polys[t]);
    };
    if (!(worst < min_angle_deg)) {
      keep();
      continue;
    }
    std::vector<Vec2> Q = B.P;
    std::vector<std::array<int, 2>> boundary;
    std::map<std::pair<int, int>, std::vector<int>> splits;
    for (int t : tris)
      for (int i = 0; i < 3; ++i) {
        const int a = polys[t][i], b = polys[t][(i + 1) % 3];
        if (directed.count({b, a})) continue;
        const double len = (B.P[b] - B.P[a]).norm();
        const int k = front_split.count({a, b})
                          ? std::max(1, static_cast<int>(std::ceil(len / size_mm - 1e-6)))
                          : 1;
        int prev = a;
        for (int j = 1; j < k; ++j) {
          Q.push_back(B.P[a] + (B.P[b] - B.P[a]) * (static_cast<double>(j) / k));
          const int id = static_cast<int>(Q.size()) - 1;
          splits[{a, b}].push_back(id);
          boundary.push_back({prev, id});
          prev = id;
        }
        boundary.push_back({prev, b});
      }
    const detail::RegionTriangulation tri =
        detail::triangulate_region(Q, boundary, 1.25 * size_mm, min_angle_deg);
    Q.insert(Q.end(), tri.new_points.begin(), tri.new_points.end());
    double better = tri.triangles.empty() ? 0.0 : 180.0;
    for (const auto& t : tri.triangles)
      better = std::min(better, min_corner_deg(Q, {t[0], t[1], t[2]}));
    if (better <= worst) {
      keep();
      continue;
    }
    for (std::size_t k = B.P.size(); k < Q.size(); ++k) B.add_vertex(Q[k]);
    for (auto& [e, ids] : splits) front_split[e] = ids;
    for (const auto& t : tri.triangles) rebuilt.push_back({t[0], t[1], t[2]});
  }
  B.out.polygons.clear();
  B.out.polygon_stage.clear();
  B.out.polygon_layer.clear();
  B.out.polygon_expanded.clear();
  for (auto& p : rebuilt) B.add_polygon(std::move(p), 1, 0, 0);
  std::vector<int> next;
  for (std::size_t i = 0; i < front.size(); ++i) {
    next.push_back(front[i]);
    const auto& ids = front_split[{front[i], front[(i + 1) % front.size()]}];
    next.insert(next.end(), ids.begin(), ids.end());
  }
  front = std::move(next);
}

}  // namespace

SurfaceQuality surface_quality(const Eigen::MatrixX2d& xy,
                               const std::vector<std::vector<int>>& polygons) {
  SurfaceQuality q;
  q.min_angle_deg = 360;
  double sum_aspect = 0;
  for (const auto& poly : polygons) {
    const std::size_t n = poly.size();
    (n == 3 ? q.n_triangles : q.n_quads)++;
    double lmin = 1e300, lmax = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const Vec2 a = xy.row(poly[(i + n - 1) % n]), b = xy.row(poly[i]), c = xy.row(poly[(i + 1) % n]);
      const Vec2 u = a - b, v = c - b;
      const double ang = std::atan2(std::abs(cross2(u, v)), u.dot(v)) / kDeg;
      q.min_angle_deg = std::min(q.min_angle_deg, ang);
      q.max_angle_deg = std::max(q.max_angle_deg, ang);
      lmin = std::min(lmin, v.norm());
      lmax = std::max(lmax, v.norm());
    }
    const double aspect = lmax / std::max(lmin, 1e-300);
    q.max_aspect_ratio = std::max(q.max_aspect_ratio, aspect);
    sum_aspect += aspect;
  }
  q.mean_aspect_ratio = polygons.empty() ? 0 : sum_aspect / polygons.size();
  if (polygons.empty()) q.min_angle_deg = 0;
  return q;
}

namespace {

// The reference radius of a surface mesh: r_skin at the wound's centre.
double reference_radius(const WoundBorder& border, const PatientModel& model) {
  if (border.loop_theta_z.empty())
    throw InvalidInput("wound border: the loop is empty; a wound needs at least 2 points");
  double t0 = border.loop_theta_z[0].x(), sx = 0, sz = 0;
  for (const auto& p : border.loop_theta_z) {
    sx += std::remainder(p.x() - t0, 360.0);
    sz += p.y();
  }
  const double n = static_cast<double>(border.loop_theta_z.size());
  return model.r_skin(t0 + sx / n, sz / n);
}

}  // namespace

SurfaceMesh mesh_surface(const WoundBorder& border, const PatientModel& model,
                         const SurfaceMeshOptions& options) {
  return mesh_surface(border, reference_radius(border, model), options);
}

MeshOutcome<SurfaceMesh> try_mesh_surface(const WoundBorder& border, const PatientModel& model,
                                          const SurfaceMeshOptions& options) {
  return try_mesh_surface(border, reference_radius(border, model), options);
}

namespace {

void check_mesher_inputs(int n, double ref_radius_mm, const SurfaceMeshOptions& o) {
  if (n < 2)
    throw InvalidInput(cat("wound border: the loop has ", n,
                           " point(s); a wound needs at least "
                           "2 (an incision) or 3 (an excision)"));
  if (!(ref_radius_mm > 0) || !std::isfinite(ref_radius_mm))
    throw InvalidInput(cat("surface mesher: reference radius ", ref_radius_mm,
                           " mm must be positive (r_skin at the wound's centre)"));
  if (!(o.size_mm > 0) || !(o.t1_deg > 0 && o.t1_deg < 180) || !(o.t2_deg >= 0 && o.t2_deg < 180) ||
      !(o.stage1_min_angle_deg >= 0 && o.stage1_min_angle_deg <= 20.7) || !(o.growth >= 1) ||
      !(o.split_ratio > 1) || o.max_layers < 1)
    throw InvalidInput(cat("surface mesher: options out of range (size ", o.size_mm, " mm > 0, t1 ",
                           o.t1_deg, " in (0,180), stage-1 angle ", o.stage1_min_angle_deg,
                           " in [0,20.7], t2 ", o.t2_deg, " in [0,180), growth ", o.growth,
                           " >= 1, split ratio ", o.split_ratio, " > 1)"));
}

// The loop in the local tangent plane around the wound (mm; the seam at +-180 is unwrapped
// around point 0), mirrored if it runs clockwise; sets the plane's centre, the wound's size and
// B.mirrored.
std::vector<Vec2> local_plane(Builder& B, const std::vector<Eigen::Vector2d>& loop,
                              double ref_radius_mm) {
  SurfaceMesh& out = B.out;
  const int n = static_cast<int>(loop.size());
  std::vector<double> theta(n);
  double sx = 0, sz = 0;
  for (int i = 0; i < n; ++i) {
    if (!loop[i].allFinite())
      throw InvalidInput(
          cat("wound border: point ", i, " (", loop[i].x(), ", ", loop[i].y(), ") is not finite"));
    theta[i] = loop[0].x() + std::remainder(loop[i].x() - loop[0].x(), 360.0);
    sx += theta[i];
    sz += loop[i].y();
  }
  out.theta_c_deg = sx / n;
  out.z_c_mm = sz / n;
  std::vector<Vec2> L(n);
  for (int i = 0; i < n; ++i)
    L[i] = {(theta[i] - out.theta_c_deg) * kDeg * ref_radius_mm, loop[i].y() - out.z_c_mm};
  double area = 0, perimeter = 0;
  for (int i = 0; i < n; ++i) {
    const Vec2 &a = L[i], &b = L[(i + 1) % n];
    area += 0.5 * cross2(a, b);
    perimeter += (b - a).norm();
    if ((b - a).norm() < 1e-6)
      throw InvalidInput(cat("wound border: points ", i, " and ", (i + 1) % n,
                             " coincide at theta ", loop[i].x(), " deg, z ", loop[i].y(),
                             " mm; neighbouring loop points "
                             "must differ (twins are points of the other lip, not neighbours)"));
    for (int j = 0; j < n; ++j) out.wound_size_mm = std::max(out.wound_size_mm, (L[j] - a).norm());
  }
  // The plan keeps the tissue on the loop's left (a clockwise loop, docs/plan-format.md); the
  // mesher wants the hole on the left, so the loop is mirrored unless it clearly runs
  // counterclockwise. A zero-area incision (a Z-plasty's cut) is mirrored too: its area says
  // nothing, yet which lip is which matters, since the sutures name the lips by their loop
  // points (the Z-plasty's flap tips are loop points 1 and 4, not their twins 5 and 2).
  B.mirrored = !(area > 1e-9 * perimeter * perimeter);
  if (B.mirrored)
    for (auto& p : L) p.x() = -p.x();
  return L;
}

// Gives both sides of suture `s` matching nodes (`inner`, see subdivided_edges()) so that
// they pair up one to one: by arc length along each side, at the loop points of both sides (a
// run of several edges may be sewn to one edge), and evenly between them. `sewn_by` records
// which suture sews each loop edge.
void match_suture_sides(const std::vector<Vec2>& L, const std::array<int, 4>& q, std::size_t s,
                        double size_mm, std::vector<int>& sewn_by,
                        std::vector<std::vector<double>>& inner) {
  const int n = static_cast<int>(L.size());
  for (int v : q)
    if (v < 0 || v >= n)
      throw InvalidInput(cat("wound border: suture ", s, " names loop point ", v, "; the loop has ",
                             n, " points"));
  if (q[0] == q[1] || q[2] == q[3])
    throw InvalidInput(cat("wound border: suture ", s, " (", q[0], ",", q[1], ")-(", q[2], ",",
                           q[3],
                           ") has a side without an edge; each side runs from one loop "
                           "point to another"));
  const auto sides = plan::suture_edges(q, n);
  for (const auto& side : sides)
    for (int e : side) {
      if (sewn_by[e] >= 0)
        throw InvalidInput(cat("wound border: suture ", s, " sews loop edge (", e, ",", (e + 1) % n,
                               "), which suture ", sewn_by[e],
                               " sews already; each edge can be sewn once"));
      sewn_by[e] = static_cast<int>(s);
    }
  // Arc-length positions of each side's loop points, as fractions of the side.
  std::array<std::vector<double>, 2> at;
  std::array<double, 2> length{};
  for (int k = 0; k < 2; ++k) {
    at[k] = {0.0};
    for (int e : sides[k]) at[k].push_back(length[k] += (L[(e + 1) % n] - L[e]).norm());
    for (double& t : at[k]) t /= std::max(length[k], 1e-300);
  }
  // The second side runs against the loop: its fraction t along the suture is 1 - t along
  // its edges.
  for (double& t : at[1]) t = 1 - t;
  std::vector<double> breaks = at[0];
  breaks.insert(breaks.end(), at[1].begin(), at[1].end());
  std::sort(breaks.begin(), breaks.end());
  std::vector<double> T;  // the suture's nodes, fractions along it
  for (std::size_t b = 0; b + 1 < breaks.size(); ++b) {
    const double dt = breaks[b + 1] - breaks[b];
    if (dt < 1e-9) continue;
    const int k = std::max(
        1, static_cast<int>(std::ceil(dt * std::max(length[0], length[1]) / size_mm - 1e-6)));
    for (int j = 0; j < k; ++j) T.push_back(breaks[b] + dt * j / k);
  }
  T.push_back(1.0);
  // Each edge of a side gets the nodes strictly inside its stretch, in its own parameter.
  for (int k = 0; k < 2; ++k)
    for (std::size_t m = 0; m < sides[k].size(); ++m) {
      const int e = sides[k][m];
      double t0 = at[k][m], t1 = at[k][m + 1];
      inner[e].clear();
      const bool backwards = t1 < t0;
      if (backwards) std::swap(t0, t1);
      for (double t : T)
        if (t > t0 + 1e-9 && t < t1 - 1e-9) inner[e].push_back((t - t0) / (t1 - t0));
      if (backwards) {
        for (double& u : inner[e]) u = 1 - u;
        std::reverse(inner[e].begin(), inner[e].end());
      }
    }
}

// Loop edges subdivided to the mesh size: `inner[i]` are the parameters in (0, 1) of the extra
// nodes on edge i; sutured sides get matching nodes (match_suture_sides()).
std::vector<std::vector<double>> subdivided_edges(const std::vector<Vec2>& L,
                                                  const std::vector<std::array<int, 4>>& sutures,
                                                  double size_mm) {
  const int n = static_cast<int>(L.size());
  std::vector<std::vector<double>> inner(n);
  auto even = [&](int i, double len) {
    const int k = std::max(1, static_cast<int>(std::ceil(len / size_mm - 1e-6)));
    for (int j = 1; j < k; ++j) inner[i].push_back(static_cast<double>(j) / k);
  };
  for (int i = 0; i < n; ++i) even(i, (L[(i + 1) % n] - L[i]).norm());
  std::vector<int> sewn_by(n, -1);
  for (std::size_t s = 0; s < sutures.size(); ++s)
    match_suture_sides(L, sutures[s], s, size_mm, sewn_by, inner);
  return inner;
}

// The loop's nodes (the loop points first, then each edge's inner nodes) and each edge's
// chain; returns the front, the loop's nodes in order.
std::vector<int> add_loop_nodes(Builder& B, const std::vector<Vec2>& L,
                                const std::vector<std::vector<double>>& inner) {
  SurfaceMesh& out = B.out;
  const int n = static_cast<int>(L.size());
  for (int i = 0; i < n; ++i) B.add_vertex(L[i]);
  out.loop_vertex.resize(n);
  for (int i = 0; i < n; ++i) out.loop_vertex[i] = i;
  out.edge_chain.resize(n);
  std::vector<int> front;
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1) % n;
    auto& chain = out.edge_chain[i];
    chain.push_back(i);
    front.push_back(i);
    for (double t : inner[i]) {
      chain.push_back(B.add_vertex((1 - t) * L[i] + t * L[j]));
      front.push_back(chain.back());
    }
    chain.push_back(j);
  }
  return front;
}

// Stage 1: fill concave corners deeper than t1 with triangles (v_{i+2}, v_{i+1}, v_i). The paper
// walks the border in order; with subdivided edges that zips a concavity into a fan of slivers,
// so the sharpest corner is filled first, which zips it into a strip.
void fill_concave_corners(Builder& B, std::vector<int>& front, double t1_deg) {
  const double t1 = t1_deg * kDeg;
  while (front.size() > 3) {
    const std::size_t m = front.size();
    std::size_t best = m;
    double best_turn = -t1;
    for (std::size_t i = 0; i < m; ++i) {
      const int a = front[(i + m - 1) % m], b = front[i], c = front[(i + 1) % m];
      const double tau = turning(B.P[a], B.P[b], B.P[c]);
      if (!(tau < best_turn)) continue;
      bool blocked = (B.P[a] - B.P[c]).norm() < 1e-9;
      for (std::size_t k = 0; k < m && !blocked; ++k)
        blocked = point_in_triangle(B.P[front[k]], B.P[c], B.P[b], B.P[a]);
      if (blocked) continue;
      best = i;
      best_turn = tau;
    }
    if (best == m) break;
    B.add_polygon({front[(best + 1) % m], front[best], front[(best + m - 1) % m]}, 1, 0, 0);
    front.erase(front.begin() + static_cast<long>(best));
  }
}

// One layer of stage 2 and growth: quadrilaterals of depth l outward from `front`, which
// becomes the layer's outer border.
void grow_layer(Builder& B, std::vector<int>& front, double l, int layer,
                const SurfaceMeshOptions& o) {
  const double t2 = o.t2_deg * kDeg;
  const std::size_t m = front.size();
  std::vector<std::vector<int>> fan(m);
  std::vector<int> expanded(m, 0);
  for (std::size_t i = 0; i < m; ++i) {
    // copies: add_vertex() below may reallocate B.P
    const Vec2 p = B.P[front[(i + m - 1) % m]];
    const Vec2 v = B.P[front[i]];
    const Vec2 q = B.P[front[(i + 1) % m]];
    const double tau = turning(p, v, q);
    const Vec2 n1 = outward(p, v), n2 = outward(v, q);
    const double hole_angle = kPi - tau;
    if (hole_angle < t2 || 1 + n1.dot(n2) < 0.5) {
      // Expanded vertex: a fan of corner quads; two at a slit's end, where one would be flat.
      expanded[i] = 1;
      const int nq = tau > 150 * kDeg ? 2 : 1;
      const double step = tau / (2 * nq);
      // The paper's diagonal vertex v + l (n1 + n2) lies 2 cos(step) l out: a square corner at
      // step = 45 deg, a 60/120 rhombus at 60 deg (whose outer corner then turns by only
      // 60 deg, so the next layer does not expand it again). Below 45 deg, a right-angled kite.
      const double diag = step >= kPi / 4 ? std::max(1.0, 2 * std::cos(step)) : 1 / std::cos(step);
      for (int k = 0; k <= 2 * nq; ++k)
        fan[i].push_back(B.add_vertex(v + l * (k % 2 ? diag : 1.0) * rotate(n1, k * step)));
    } else {
      fan[i].push_back(B.add_vertex(v + l * (n1 + n2) / (1 + n1.dot(n2))));
    }
  }
  std::vector<int> next;
  for (std::size_t i = 0; i < m; ++i) {
    const int v = front[i];
    if (expanded[i])
      for (std::size_t k = 0; k + 2 < fan[i].size(); k += 2)
        B.add_polygon({v, fan[i][k], fan[i][k + 1], fan[i][k + 2]}, 2, layer, 1);
    next.insert(next.end(), fan[i].begin(), fan[i].end());
    const int a = v, b = front[(i + 1) % m];
    const int a2 = fan[i].back(), b2 = fan[(i + 1) % m].front();
    if ((B.P[b2] - B.P[a2]).norm() > o.split_ratio * l) {
      const int mid = B.add_vertex(0.5 * (B.P[a2] + B.P[b2]));
      B.add_polygon({a, a2, mid, b}, 2, layer, 0);
      B.add_polygon({b, mid, b2}, 2, layer, 0);
      next.push_back(mid);
    } else {
      B.add_polygon({a, a2, b2, b}, 2, layer, 0);
    }
  }
  B.check_simple(next, layer);
  front = std::move(next);
}

// Stage 2 and growth: layers of quadrilaterals until the extent is reached; returns the
// number of layers (B.refusal set if a layer folds or the layers do not reach the extent).
int grow_layers(Builder& B, std::vector<int>& front, const SurfaceMeshOptions& o) {
  const double extent_mm = B.out.extent_mm;
  double l = o.size_mm, reached = 0;
  int layer = 0;
  while (reached < extent_mm - 1e-9 && layer < o.max_layers) {
    ++layer;
    grow_layer(B, front, l, layer, o);
    if (B.refusal) return layer;
    reached += l;
    const double remaining = extent_mm - reached;
    double l_next = std::min(l * o.growth, std::max(l, median_edge(B.P, front)));
    if (remaining < 1.5 * l_next) l_next = remaining;
    l = l_next;
  }
  if (reached < extent_mm - 1e-9)
    B.refusal = MeshRefusal{MeshRefusal::Kind::Unreached, NAN, NAN,
                            cat("surface mesher: ", o.max_layers, " layers reach only ",
                                std::round(reached * 10) / 10, " of the ",
                                std::round(extent_mm * 10) / 10,
                                " mm extent; use a larger {mesh_size} or a smaller {extent}")};
  return layer;
}

// The vertices in (theta, z) and in the plane, unmirrored, and the quality.
void finish_surface(Builder& B) {
  SurfaceMesh& out = B.out;
  const int nv = static_cast<int>(B.P.size());
  out.xy_mm.resize(nv, 2);
  out.theta_z.resize(nv, 2);
  for (int i = 0; i < nv; ++i) {
    out.theta_z.row(i) = B.theta_z(B.P[i]).transpose();
    out.xy_mm.row(i) << (B.mirrored ? -B.P[i].x() : B.P[i].x()), B.P[i].y();
  }
  if (B.mirrored) {
    for (auto& poly : out.polygons) std::reverse(poly.begin(), poly.end());
    std::reverse(out.outer_border.begin(), out.outer_border.end());
  }
  out.quality = surface_quality(out.xy_mm, out.polygons);
}

}  // namespace

MeshOutcome<SurfaceMesh> try_mesh_surface(const WoundBorder& border, double ref_radius_mm,
                                          const SurfaceMeshOptions& o) {
  check_mesher_inputs(static_cast<int>(border.loop_theta_z.size()), ref_radius_mm, o);
  Builder B;
  SurfaceMesh& out = B.out;
  out.ref_radius_mm = ref_radius_mm;
  out.sutures = border.sutures;
  const std::vector<Vec2> L = local_plane(B, border.loop_theta_z, ref_radius_mm);
  for (const auto& flap : border.flaps_theta_z) {
    out.flaps_theta_z.emplace_back();
    for (const auto& p : flap)
      out.flaps_theta_z.back().push_back(
          {out.theta_c_deg + std::remainder(p.x() - out.theta_c_deg, 360.0), p.y()});
  }
  out.extent_mm = o.extent_mm > 0 ? o.extent_mm : 3.0 * out.wound_size_mm;
  const auto refused = [&B] { return MeshOutcome<SurfaceMesh>{std::nullopt, *B.refusal}; };
  std::vector<int> front = add_loop_nodes(B, L, subdivided_edges(L, border.sutures, o.size_mm));
  fill_concave_corners(B, front, o.t1_deg);
  if (B.refusal) return refused();
  // A ladder of thin triangles across a large flap is rebuilt with interior points.
  if (o.stage1_min_angle_deg > 0) rebuild_stage1(B, front, o.stage1_min_angle_deg, o.size_mm);
  if (B.refusal) return refused();
  out.n_layers = grow_layers(B, front, o);
  if (B.refusal) return refused();
  out.outer_border = front;
  finish_surface(B);
  return {std::move(B.out), {}};
}

SurfaceMesh mesh_surface(const WoundBorder& border, double ref_radius_mm,
                         const SurfaceMeshOptions& o) {
  MeshOutcome<SurfaceMesh> outcome = try_mesh_surface(border, ref_radius_mm, o);
  if (!outcome) throw InvalidParameter(outcome.refusal.message);  // never OffModel
  return std::move(*outcome.mesh);
}

}  // namespace caps::mesher

#include "caps/render/skin_surface.hpp"

#include "caps/closure/face_domain.hpp"

#include "caps/core/error.hpp"
#include "caps/core/plane_geometry.hpp"
#include "caps/core/units.hpp"
#include "caps/render/drawn_skin.hpp"
#include "caps/fem/elements.hpp"
#include "caps/surface/patient_model.hpp"

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <set>

namespace caps::render {
namespace {

using CdtKernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<
    CdtKernel,
    CGAL::Triangulation_data_structure_2<
        CGAL::Triangulation_vertex_base_with_info_2<int, CdtKernel>,
        CGAL::Constrained_triangulation_face_base_2<
            CdtKernel, CGAL::Triangulation_face_base_with_info_2<int, CdtKernel>>>,
    CGAL::Exact_predicates_tag>;
using CdtPoint = CdtKernel::Point_2;

// A skin tone for models without colour (CT, MR): sRGB of light skin.
const Eigen::Vector3d kSkinTone(0.87, 0.70, 0.60);

struct Builder {
  std::vector<Eigen::Vector3d> pre, post, color, offset;
  std::vector<Eigen::Vector2d> theta_z, natural;
  std::vector<int> element;
  std::vector<Eigen::Vector3i> faces;
  std::vector<SkinPart> part;
  std::vector<int> cap_centres;  // the vertices on the axis closing the range mesh's ends
  std::vector<std::pair<int, Eigen::Vector3d>> given_normals;  // the isosurface's vertices

  int add(const Eigen::Vector3d& p, const Eigen::Vector3d& q, const Eigen::Vector3d& c,
          const Eigen::Vector3d& d, const Eigen::Vector2d& tz, int e,
          const Eigen::Vector2d& xi = Eigen::Vector2d::Zero()) {
    pre.push_back(p);
    post.push_back(q);
    color.push_back(c);
    offset.push_back(d);
    theta_z.push_back(tz);
    element.push_back(e);
    natural.push_back(xi);
    return static_cast<int>(pre.size()) - 1;
  }
  void tri(int a, int b, int c, SkinPart p) {
    if (a == b || b == c || a == c) return;
    faces.emplace_back(a, b, c);
    part.push_back(p);
  }
};

// A grid column index j (unwrapped around the mesh) brought into 0..nt-1.
long wrapped(long j, long nt) { return ((j % nt) + nt) % nt; }

double wrap180(double deg) {
  double t = std::fmod(deg + 180.0, 360.0);
  if (t < 0) t += 360.0;
  return t - 180.0;
}

double signed_area(const std::vector<Eigen::Vector2d>& poly) {
  double a = 0;
  for (std::size_t i = 0; i < poly.size(); ++i) {
    const auto& p = poly[i];
    const auto& q = poly[(i + 1) % poly.size()];
    a += p.x() * q.y() - q.x() * p.y();
  }
  return 0.5 * a;
}

double cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  return (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
}

// Ear clipping of a counter-clockwise polygon; returns index triples into `poly`. Of the valid
// ears the one of least `cost` goes first: with the post-operative area as the cost, a wound is
// zipped up from its tips, so that its fill collapses when the lips meet. Falls back to a fan
// when no ear is found (degenerate loops such as an incision's coincident lips).
template <typename Cost>
std::vector<std::array<int, 3>> ear_clip(const std::vector<Eigen::Vector2d>& poly, Cost&& cost) {
  std::vector<std::array<int, 3>> out;
  std::vector<int> idx(poly.size());
  for (std::size_t i = 0; i < idx.size(); ++i) idx[i] = static_cast<int>(i);
  while (idx.size() > 3) {
    const std::size_t n = idx.size();
    std::size_t best = n;
    double best_cost = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const int a = idx[(i + n - 1) % n], b = idx[i], c = idx[(i + 1) % n];
      if (cross2(poly[a], poly[b], poly[c]) <= 0) continue;
      bool empty = true;
      for (int k : idx) {
        if (k == a || k == b || k == c) continue;
        const Eigen::Vector2d& p = poly[k];
        if (cross2(poly[a], poly[b], p) >= 0 && cross2(poly[b], poly[c], p) >= 0 &&
            cross2(poly[c], poly[a], p) >= 0) {
          empty = false;
          break;
        }
      }
      if (!empty) continue;
      const double c_abc = cost(a, b, c);
      if (best == n || c_abc < best_cost) {
        best = i;
        best_cost = c_abc;
      }
    }
    if (best == n) {
      for (std::size_t i = 1; i + 1 < idx.size(); ++i) out.push_back({idx[0], idx[i], idx[i + 1]});
      return out;
    }
    out.push_back({idx[(best + n - 1) % n], idx[best], idx[(best + 1) % n]});
    idx.erase(idx.begin() + static_cast<std::ptrdiff_t>(best));
  }
  if (idx.size() == 3) out.push_back({idx[0], idx[1], idx[2]});
  return out;
}

// The face nodes (corners then mid-edge nodes) of an element's top face; none for a Tet10,
// which has no top face (fem/mesh.hpp).
std::vector<int> top_face_local(fem::ElementType t) {
  switch (t) {
    case fem::ElementType::Hex20: return {0, 1, 2, 3, 8, 9, 10, 11};
    case fem::ElementType::Wedge15: return {0, 1, 2, 6, 7, 8};
    case fem::ElementType::Tet10: return {};
  }
  return {};
}

}  // namespace

std::vector<int> skin_elements(const PatientModel& model, const fem::Mesh& mesh) {
  std::vector<int> out;
  for (std::size_t e = 0; e < mesh.elements.size(); ++e) {
    const fem::Element& el = mesh.elements[e];
    const std::vector<int> face = top_face_local(el.type);
    bool on = !face.empty();
    for (int a : face) {
      const CylindricalPoint c = model.to_cylindrical(mesh.nodes.row(el.nodes[a]).transpose());
      if (!(std::abs(c.r_mm - model.r_skin(c.theta_deg, c.z_mm)) <= kOnSkinToleranceMm)) {
        on = false;
        break;
      }
    }
    if (on) out.push_back(static_cast<int>(e));
  }
  if (out.empty())
    throw InvalidInput(cat("render: no element of the mesh (", mesh.n_elements(),
                           " elements) has its top face on the model's skin; is it the mesh of "
                           "this model?"));
  return out;
}

int full_resolution_subdivisions(const PatientModel& model, const fem::Mesh& mesh) {
  double longest = 0, radius = 0;
  int n_corners = 0;
  for (int e : skin_elements(model, mesh)) {
    const fem::Element& el = mesh.elements[e];
    const int nc = el.type == fem::ElementType::Hex20 ? 4 : 3;
    for (int a = 0; a < nc; ++a) {
      const Eigen::Vector3d p = mesh.nodes.row(el.nodes[a]);
      longest = std::max(longest, (p - mesh.nodes.row(el.nodes[(a + 1) % nc]).transpose()).norm());
      radius += model.to_cylindrical(p).r_mm;
      ++n_corners;
    }
  }
  radius /= n_corners;
  const double spacing = std::min(model.grid().dz_mm, deg_to_rad(model.grid().dtheta_deg()) * radius);
  return std::clamp(static_cast<int>(std::ceil(longest / spacing)), 1, 64);
}

SkinSurfaces displaced_skin(const PatientModel& model, const fem::Mesh& mesh,
                            const fem::SolveResult* result, int n_subdivisions,
                            const DrawnSkin* drawn, SkinExtent extent) {
  return displaced_skin(model, mesh, result ? &result->displacement_mm : nullptr, n_subdivisions,
                        drawn, extent);
}

Eigen::MatrixX3d vertex_normals(const TriMesh& m) {
  Eigen::MatrixX3d N = Eigen::MatrixX3d::Zero(m.V.rows(), 3);
  for (Eigen::Index f = 0; f < m.F.rows(); ++f) {
    const Eigen::Vector3d a = m.V.row(m.F(f, 0)), b = m.V.row(m.F(f, 1)), c = m.V.row(m.F(f, 2));
    const Eigen::Vector3d n = (b - a).cross(c - a);  // area-weighted
    for (int k = 0; k < 3; ++k) N.row(m.F(f, k)) += n.transpose();
  }
  for (Eigen::Index v = 0; v < N.rows(); ++v) {
    const double l = N.row(v).norm();
    if (l > 0) N.row(v) /= l;
  }
  return N;
}

Eigen::MatrixX3d shading_normals(const SkinSurfaces& skin, double t) {
  const bool given = skin.normal_pre.rows() == skin.pre.V.rows() &&
                     skin.normal_post.rows() == skin.pre.V.rows();
  if (!given) {
    TriMesh m{skin.pre.V + t * (skin.post.V - skin.pre.V), skin.pre.F};
    return vertex_normals(m);
  }
  Eigen::MatrixX3d N = (1.0 - t) * skin.normal_pre + t * skin.normal_post;
  for (Eigen::Index v = 0; v < N.rows(); ++v) {
    const double l = N.row(v).norm();
    if (l > 0) N.row(v) /= l;
  }
  return N;
}

namespace {

void check_skin_inputs(const fem::Mesh& mesh, const Eigen::MatrixX3d* displacement_mm, int n) {
  if (n < 1 || n > 64)
    throw InvalidInput(cat("render: subdivisions ", n, " must be in 1..64 per element edge"));
  if (displacement_mm) {
    if (displacement_mm->rows() != mesh.n_nodes())
      throw InvalidInput(cat("render: the displacement has ", displacement_mm->rows(),
                             " rows but the mesh has ", mesh.n_nodes(), " nodes"));
    if (!displacement_mm->allFinite())
      throw InvalidInput("render: the displacement has non-finite values");
  }
}

// The model's colour at (theta deg, z mm), or a skin tone for models without colour.
Eigen::Vector3d skin_color(const PatientModel& model, double theta, double z) {
  return model.has_color() ? model.color_at(theta, z) : kSkinTone;
}

// The centroid of the skin elements' top-face nodes (LPS mm).
Eigen::Vector3d top_face_centre(const fem::Mesh& mesh, const std::vector<int>& elements) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  int n_face_nodes = 0;
  for (int e : elements)
    for (int a : top_face_local(mesh.elements[e].type)) {
      centre += mesh.nodes.row(mesh.elements[e].nodes[a]).transpose();
      ++n_face_nodes;
    }
  return centre / n_face_nodes;
}

// The drawn range surface's normals at its grid vertices (central differences, periodic in
// theta, one-sided at the first and last rows), interpolated bilinearly in between: one smooth
// normal field for the range cells, the seam and the micropolygons alike.
class NormalField {
 public:
  explicit NormalField(const PatientModel& skin) : skin_(skin), g_(skin.grid()) {
    const auto& r = skin.maps().r_skin;
    N_.resize(g_.size());
    const double dth = deg_to_rad(g_.dtheta_deg());
    for (int k = 0; k < g_.n_z; ++k)
      for (int j = 0; j < g_.n_theta; ++j) {
        const int jp = (j + 1) % g_.n_theta, jm = (j + g_.n_theta - 1) % g_.n_theta;
        const int kp = std::min(k + 1, g_.n_z - 1), km = std::max(k - 1, 0);
        const double rr = r[g_.index(j, k)];
        const double dr_dth = (r[g_.index(jp, k)] - r[g_.index(jm, k)]) / (2 * dth);
        const double dr_dz =
            kp > km ? (r[g_.index(j, kp)] - r[g_.index(j, km)]) / ((kp - km) * g_.dz_mm) : 0.0;
        const Eigen::Vector3d e_r = skin.axis().ray(deg_to_rad(g_.theta_deg(j)));
        const Eigen::Vector3d e_z = skin.axis().direction;
        const Eigen::Vector3d e_th = e_z.cross(e_r);
        N_[g_.index(j, k)] = (e_r - (rr > 1.0 ? dr_dth / rr : 0.0) * e_th - dr_dz * e_z).normalized();
      }
  }
  Eigen::Vector3d at(double theta_deg, double z_mm) const {
    double u = (theta_deg - g_.theta0_deg) / g_.dtheta_deg();
    u -= g_.n_theta * std::floor(u / g_.n_theta);
    int j0 = static_cast<int>(std::floor(u));
    if (j0 >= g_.n_theta) j0 = 0;
    const int j1 = (j0 + 1) % g_.n_theta;
    const double v = std::clamp((z_mm - g_.z0_mm) / g_.dz_mm, 0.0, double(g_.n_z - 1));
    const int k0 = std::min(static_cast<int>(std::floor(v)), std::max(g_.n_z - 2, 0));
    const int k1 = std::min(k0 + 1, g_.n_z - 1);
    const double fu = u - j0, fv = v - k0;
    const Eigen::Vector3d n =
        (1 - fv) * ((1 - fu) * N_[g_.index(j0, k0)] + fu * N_[g_.index(j1, k0)]) +
        fv * ((1 - fu) * N_[g_.index(j0, k1)] + fu * N_[g_.index(j1, k1)]);
    return n.normalized();
  }

 private:
  const PatientModel& skin_;  // not owned
  const CylinderGrid& g_;     // not owned
  std::vector<Eigen::Vector3d> N_;
};

// One skin element's top face as (n + 1)^2 (hex) or (n + 1)(n + 2)/2 (wedge) micropolygon
// vertices, welded to those its neighbours left on shared edges, and their triangles.
class FaceSampler {
 public:
  FaceSampler(Builder& b, std::map<std::array<long, 3>, int>& welded, const PatientModel& model,
              const PatientModel& drawn, const fem::Mesh& mesh,
              const Eigen::MatrixX3d* displacement_mm, int e, int n, double theta_c)
      : b_(b),
        welded_(welded),
        model_(model),
        drawn_(drawn),
        el_(mesh.elements[e]),
        e_(e),
        n_(n),
        theta_c_(theta_c),
        hex_(el_.type == fem::ElementType::Hex20),
        X_(fem::element_coordinates(mesh, e)),
        U_(Eigen::MatrixX3d::Zero(el_.n_nodes(), 3)) {
    if (displacement_mm)
      for (int a = 0; a < el_.n_nodes(); ++a) U_.row(a) = displacement_mm->row(el_.nodes[a]);
  }

  void add_triangles() {
    const int n = n_;
    if (hex_) {
      std::vector<int> id((n + 1) * (n + 1));
      for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) id[j * (n + 1) + i] = vertex(i, j);
      auto at = [&](int i, int j) { return id[j * (n + 1) + i]; };
      // the face's 0-1-2-3 normal points into the element: reverse it to face outwards
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          b_.tri(at(i, j), at(i, j + 1), at(i + 1, j + 1), SkinPart::Micropolygon);
          b_.tri(at(i, j), at(i + 1, j + 1), at(i + 1, j), SkinPart::Micropolygon);
        }
    } else {
      std::map<std::pair<int, int>, int> id;
      for (int j = 0; j <= n; ++j)
        for (int i = 0; i + j <= n; ++i) id[{i, j}] = vertex(i, j);
      for (int j = 0; j < n; ++j)
        for (int i = 0; i + j < n; ++i) {
          b_.tri(id[{i, j}], id[{i, j + 1}], id[{i + 1, j}], SkinPart::Micropolygon);
          if (i + j + 1 < n)
            b_.tri(id[{i + 1, j}], id[{i, j + 1}], id[{i + 1, j + 1}], SkinPart::Micropolygon);
        }
    }
  }

 private:
  // key of a point t/n along the edge between local nodes la and lb (lower node id first)
  std::array<long, 3> edge_key(int la, int lb, int t) const {
    const long a = el_.nodes[la], c = el_.nodes[lb];
    if (t == 0) return {a, -1, -1};
    if (t == n_) return {c, -1, -1};
    return a < c ? std::array<long, 3>{a, c, t} : std::array<long, 3>{c, a, n_ - t};
  }
  // key of the grid point (i, j): a corner node, an edge point, or none
  std::array<long, 3> key_of(int i, int j) const {
    const int n = n_;
    if (hex_) {
      if (j == 0) return edge_key(0, 1, i);
      if (i == n) return edge_key(1, 2, j);
      if (j == n) return edge_key(3, 2, i);
      if (i == 0) return edge_key(0, 3, j);
    } else {
      if (j == 0) return edge_key(0, 1, i);
      if (i + j == n) return edge_key(1, 2, j);
      if (i == 0) return edge_key(0, 2, j);
    }
    return {-1, -1, -1};
  }
  int vertex(int i, int j) {
    const int n = n_;
    const std::array<long, 3> key = key_of(i, j);
    if (key[0] >= 0) {
      const auto it = welded_.find(key);
      if (it != welded_.end()) return it->second;
    }
    const Eigen::Vector3d xi = hex_ ? Eigen::Vector3d(-1.0 + 2.0 * i / n, -1.0 + 2.0 * j / n, -1.0)
                                    : Eigen::Vector3d(double(i) / n, double(j) / n, -1.0);
    fem::shape_functions(el_.type, xi, N_, dN_);
    const Eigen::Vector3d x_face = X_.transpose() * N_;
    const Eigen::Vector3d u = U_.transpose() * N_;
    const CylindricalPoint c = model_.to_cylindrical(x_face);
    const Eigen::Vector3d s = drawn_.skin_point(c.theta_deg, c.z_mm);
    const Eigen::Vector3d d = s - x_face;
    // theta unwrapped around the mesh's centre, so a mesh across the seam (+-180) stays in one
    // piece; post = x_face + u + d (paper section 4), pre is the same with u = 0
    const int v = b_.add(x_face + d, (x_face + u) + d, skin_color(drawn_, c.theta_deg, c.z_mm), d,
                         {theta_c_ + wrap180(c.theta_deg - theta_c_), c.z_mm}, e_, xi.head<2>());
    if (key[0] >= 0) welded_.emplace(key, v);
    return v;
  }

  Builder& b_;                                  // not owned; outlives the sampler
  std::map<std::array<long, 3>, int>& welded_;  // not owned; shared by all elements
  const PatientModel& model_;                   // not owned
  const PatientModel& drawn_;                   // not owned: the skin drawn (model_'s grid)
  const fem::Element& el_;                      // not owned
  int e_, n_;
  double theta_c_;
  bool hex_;
  Eigen::MatrixX3d X_, U_;
  Eigen::VectorXd N_;
  Eigen::MatrixX3d dN_;
};

// The border loops of the micropolygon skin, each following its faces' directed edges: the
// outer rim runs counter-clockwise in (theta, z), the wounds clockwise.
std::vector<std::vector<int>> border_loops(const std::vector<Eigen::Vector3i>& faces) {
  std::set<std::pair<int, int>> directed;
  for (const auto& f : faces)
    for (int k = 0; k < 3; ++k) directed.insert({f[k], f[(k + 1) % 3]});
  std::multimap<int, int> next;
  for (const auto& [a, c] : directed)
    if (!directed.count({c, a})) next.emplace(a, c);
  std::vector<std::vector<int>> loops;
  while (!next.empty()) {
    std::vector<int> loop;
    int v = next.begin()->first;
    const int start = v;
    while (true) {
      const auto it = next.find(v);
      if (it == next.end()) break;
      loop.push_back(v);
      v = it->second;
      next.erase(it);
      if (v == start) break;
    }
    if (loop.size() >= 2) loops.push_back(std::move(loop));
  }
  return loops;
}

std::vector<Eigen::Vector2d> loop_theta_z(const Builder& b, const std::vector<int>& loop) {
  std::vector<Eigen::Vector2d> p;
  for (int v : loop) p.push_back(b.theta_z[v]);
  return p;
}

// The loop of largest counter-clockwise area: the outer rim.
int outer_rim(const Builder& b, const std::vector<std::vector<int>>& loops) {
  int rim = -1;
  double rim_area = 0;
  for (std::size_t l = 0; l < loops.size(); ++l) {
    const double a = signed_area(loop_theta_z(b, loops[l]));
    if (a > rim_area) {
      rim_area = a;
      rim = static_cast<int>(l);
    }
  }
  if (rim < 0)
    throw InvalidInput(
        "render: the mesh's skin faces have no counter-clockwise outer rim; are "
        "the elements oriented as in docs/mesh-format.md?");
  return rim;
}

// A wound is closed when after the closure its border vertices have met another (within
// kMetMm) nearly everywhere and none is left kOpenMm from every other. Sewn nodes meet to the
// solver's tolerance, but the lips' curves between them need not: on Cranium's bilobed flap the
// closed lips' micropolygon vertices lie up to 0.24 mm apart, and on a 3 mm mesh of the same
// flap three of 136 lie 0.7-1.4 mm from any other where lips of unequal length meet. A wound
// left open (a prestretched cut without sutures) gapes by millimetres along its whole length.
constexpr double kMetMm = 0.5, kOpenMm = 2.0, kMetFraction = 0.95;

void add_wound_fills(Builder& b, const std::vector<std::vector<int>>& loops, int rim) {
  for (std::size_t l = 0; l < loops.size(); ++l) {
    if (static_cast<int>(l) == rim) continue;
    std::vector<int> loop = loops[l];
    const std::vector<Eigen::Vector2d> xy = loop_theta_z(b, loop);
    const double area = signed_area(xy);
    if (area > 0) continue;  // a second island; leave it open
    // An incision without excision (a Z-plasty, a V-Y flap) opens no hole: its lips are the skin
    // on either side, which the closure moves onto other lips. A fill there could only be a fan
    // across the flaps, so none is made.
    double perimeter = 0;
    for (std::size_t i = 0; i < xy.size(); ++i)
      perimeter += (xy[(i + 1) % xy.size()] - xy[i]).norm();
    if (-area < 1e-6 * perimeter * perimeter) continue;
    std::reverse(loop.begin(), loop.end());
    auto post_area = [&](int a, int c, int d) {
      const Eigen::Vector3d& pa = b.post[loop[a]];
      return (b.post[loop[c]] - pa).cross(b.post[loop[d]] - pa).norm();
    };
    const auto tris = ear_clip(loop_theta_z(b, loop), post_area);
    // A closed wound whose fill does not collapse with it (a transposition flap: the defect's
    // border is sewn round the first lobe, so its fill would lie across the lobes after the
    // closure, a fan of flat triangles cutting through the curved skin) gets a fill of its own
    // vertices: where the loop's are before the closure, and gathered at one point (no area, not
    // drawn) after it. An open wound's fill keeps following its border.
    double pre_fill = 0, post_fill = 0;
    for (const auto& t : tris) {
      pre_fill += (b.pre[loop[t[1]]] - b.pre[loop[t[0]]]).cross(b.pre[loop[t[2]]] - b.pre[loop[t[0]]]).norm();
      post_fill += post_area(t[0], t[1], t[2]);
    }
    // A fill that collapses with the closed wound keeps a sliver of its area (an ellipse's: up to
    // 0.3 %, where the lips' curves between sewn nodes differ); a transposition flap's keeps most
    // of it (79 % on a cylinder, 116 % on Cranium's nasal sidewall). Only such a fill needs its
    // own vertices, and the (quadratic) check that the wound is closed.
    constexpr double kKeptFillFraction = 0.1;
    const auto closed = [&] {
      int met = 0;
      for (std::size_t i = 0; i < loop.size(); ++i) {
        double nearest = 1e300;
        for (std::size_t k = 0; k < loop.size(); ++k)
          if (k != i) nearest = std::min(nearest, (b.post[loop[k]] - b.post[loop[i]]).norm());
        if (!(nearest < kOpenMm)) return false;
        met += nearest < kMetMm;
      }
      return met >= kMetFraction * static_cast<double>(loop.size());
    };
    std::vector<int> fill = loop;
    if (post_fill > kKeptFillFraction * pre_fill && closed()) {
      Eigen::Vector3d gathered = Eigen::Vector3d::Zero();
      for (int v : loop) gathered += b.post[v];
      gathered /= static_cast<double>(loop.size());
      for (int& v : fill) {
        const Eigen::Vector3d p = b.pre[v], c = b.color[v], d = b.offset[v];  // copies: add() grows
        const Eigen::Vector2d tz = b.theta_z[v], xi = b.natural[v];
        v = b.add(p, gathered, c, d, tz, b.element[v], xi);
      }
    }
    for (const auto& t : tris) b.tri(fill[t[0]], fill[t[1]], fill[t[2]], SkinPart::WoundFill);
  }
}

// The range mesh's vertices, one per sample of the model's grid: all of them from `first` on
// (the constructor), or, for SkinExtent::Patch, each added when first asked for.
class RangeVertices {
 public:
  RangeVertices(Builder& b, const PatientModel& model, bool all)
      : b_(b), model_(model), nt_(model.grid().n_theta), first_(static_cast<int>(b.pre.size())),
        all_(all) {
    if (!all_) return;
    const CylinderGrid& g = model.grid();
    for (int k = 0; k < g.n_z; ++k)
      for (int j = 0; j < g.n_theta; ++j) add(j, k);
  }
  // the vertex of sample (j, k); j wraps around
  int at(long j, long k) {
    const long jj = wrapped(j, nt_);
    if (all_) return first_ + static_cast<int>(k * nt_ + jj);
    const auto [it, added] = made_.try_emplace(k * nt_ + jj, 0);
    if (added) it->second = add(jj, k);
    return it->second;
  }

 private:
  int add(long j, long k) {
    const CylinderGrid& g = model_.grid();
    const double th = g.theta_deg(static_cast<int>(j)), z = g.z_mm(static_cast<int>(k));
    const Eigen::Vector3d s = model_.skin_point(th, z);
    return b_.add(s, s, skin_color(model_, th, z), Eigen::Vector3d::Zero(), {th, z}, -1);
  }
  Builder& b_;                  // not owned; outlives this
  const PatientModel& model_;   // not owned
  long nt_;
  int first_;
  bool all_;
  std::map<long, int> made_;    // sample k n_theta + j -> vertex (Patch)
};

// (theta deg, z mm) of range grid vertex (j, k), j unwrapped.
Eigen::Vector2d grid_corner(const CylinderGrid& g, long j, long k) {
  return Eigen::Vector2d(g.theta0_deg + j * g.dtheta_deg(), g.z0_mm + k * g.dz_mm);
}

// Range cells (j, k) removed under the mesh's footprint, in the box j0..j1 × k0..k1 of cells
// (j unwrapped around the mesh); cell (j, k) spans grid vertices j..j+1, k..k+1.
struct Footprint {
  long j0 = 0, j1 = 0, k0 = 0, k1 = 0, W = 0, H = 0;
  std::vector<char> R;

  bool in_box(long j, long k) const { return j >= j0 && j <= j1 && k >= k0 && k <= k1; }
  std::size_t index(long j, long k) const {
    return static_cast<std::size_t>((k - k0) * W + (j - j0));
  }
  char& cell(long j, long k) { return R[index(j, k)]; }
  char cell(long j, long k) const { return R[index(j, k)]; }
  // In the footprint in unwrapped cell indices; a cell may be reached one turn away.
  bool removed(long j, long k, long nt) const {
    for (long t : {j, j - nt, j + nt})
      if (in_box(t, k) && cell(t, k)) return true;
    return false;
  }
  // Marks every cell not reachable from the box's border through unmarked cells.
  void fill_holes() {
    std::vector<char> outside(R.size(), 0);
    std::vector<std::pair<long, long>> stack;
    for (long k = k0; k <= k1; ++k)
      for (long j = j0; j <= j1; ++j)
        if ((k == k0 || k == k1 || j == j0 || j == j1) && !cell(j, k)) stack.push_back({j, k});
    while (!stack.empty()) {
      const auto [j, k] = stack.back();
      stack.pop_back();
      const auto c = index(j, k);
      if (outside[c] || R[c]) continue;
      outside[c] = 1;
      for (const auto& [dj, dk] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}})
        if (in_box(j + dj, k + dk)) stack.push_back({j + dj, k + dk});
    }
    for (std::size_t c = 0; c < R.size(); ++c)
      if (!outside[c]) R[c] = 1;
  }
};

// The cells touching the rim polygon, dilated by one, holes filled, diagonal pinches removed
// so that their border is one simple loop.
Footprint footprint_cells(const CylinderGrid& g, const std::vector<Eigen::Vector2d>& rim_poly) {
  double tmin = 1e300, tmax = -1e300, zmin = 1e300, zmax = -1e300;
  for (const auto& p : rim_poly) {
    tmin = std::min(tmin, p.x());
    tmax = std::max(tmax, p.x());
    zmin = std::min(zmin, p.y());
    zmax = std::max(zmax, p.y());
  }
  const double dth = g.dtheta_deg();
  Footprint fp;
  fp.j0 = static_cast<long>(std::floor((tmin - g.theta0_deg) / dth)) - 3;
  fp.j1 = static_cast<long>(std::floor((tmax - g.theta0_deg) / dth)) + 3;
  fp.k0 = static_cast<long>(std::floor((zmin - g.z0_mm) / g.dz_mm)) - 3;
  fp.k1 = static_cast<long>(std::floor((zmax - g.z0_mm) / g.dz_mm)) + 3;
  const long j0 = fp.j0, j1 = fp.j1, k0 = fp.k0, k1 = fp.k1;
  if (k0 < 0 || k1 > g.n_z - 2 || j1 - j0 >= g.n_theta - 2)
    throw InvalidInput(cat("render: the mesh (z ", zmin, "..", zmax, " mm, theta ", tmin, "..",
                           tmax,
                           " deg) comes within 3 rows of the model's z range or wraps "
                           "around the head; the skin cannot be stitched there"));
  const long W = fp.W = j1 - j0 + 1, H = fp.H = k1 - k0 + 1;
  fp.R.assign(static_cast<std::size_t>(W * H), 0);
  std::vector<char> corner_in(static_cast<std::size_t>((W + 1) * (H + 1)));
  for (long k = k0; k <= k1 + 1; ++k)
    for (long j = j0; j <= j1 + 1; ++j)
      corner_in[static_cast<std::size_t>((k - k0) * (W + 1) + (j - j0))] =
          point_in_polygon(rim_poly, grid_corner(g, j, k));
  for (long k = k0; k <= k1; ++k)
    for (long j = j0; j <= j1; ++j)
      for (long dk = 0; dk <= 1; ++dk)
        for (long dj = 0; dj <= 1; ++dj)
          if (corner_in[static_cast<std::size_t>((k + dk - k0) * (W + 1) + (j + dj - j0))])
            fp.cell(j, k) = 1;
  for (const auto& p : rim_poly) {
    const long j = static_cast<long>(std::floor((p.x() - g.theta0_deg) / dth));
    const long k = static_cast<long>(std::floor((p.y() - g.z0_mm) / g.dz_mm));
    if (fp.in_box(j, k)) fp.cell(j, k) = 1;
  }
  const std::vector<char> seed = fp.R;
  for (long k = k0 + 1; k < k1; ++k)
    for (long j = j0 + 1; j < j1; ++j)
      if (seed[fp.index(j, k)])
        for (long dk = -1; dk <= 1; ++dk)
          for (long dj = -1; dj <= 1; ++dj) fp.cell(j + dj, k + dk) = 1;
  fp.fill_holes();
  for (bool changed = true; changed;) {
    changed = false;
    for (long k = k0; k < k1; ++k)
      for (long j = j0; j < j1; ++j) {
        const char a = fp.cell(j, k), c = fp.cell(j + 1, k), d = fp.cell(j, k + 1),
                   e = fp.cell(j + 1, k + 1);
        if ((a && e && !c && !d) || (c && d && !a && !e)) {
          fp.cell(j, k) = fp.cell(j + 1, k) = fp.cell(j, k + 1) = fp.cell(j + 1, k + 1) = 1;
          changed = true;
        }
      }
    if (changed) fp.fill_holes();
  }
  return fp;
}

// Cells this close to the footprint are drawn by the range mesh, not by the drawn skin's
// isosurface, unless the range image sees them grazing (see range_around_footprint()).
constexpr long kRangeAroundFootprint = 3;

// The undercut cells (`undercut`, as DrawnSkin::undercut_cells: the undercuts dilated by two
// cells) within kRangeAroundFootprint cells of the footprint are cleared, so that the range
// mesh draws them, but where a corner's ray grazes the skin (kGrazing: a silhouette the range
// image draws as a staircase). Returns the cells within one cell less whose isosurface is then
// left out: the range mesh and the isosurface overlap by one cell, as elsewhere. Without this
// the seam, which joins the patch's rim to range vertices, lay under isosurface triangles: a
// patch beside undercuts (a local chart's on the side of the nose) showed a ring of shards
// around it (issue 34).
std::vector<char> range_around_footprint(const PatientModel& skin, const Footprint& fp,
                                         std::vector<std::uint8_t>& undercut) {
  const CylinderGrid& g = skin.grid();
  const auto& flags = skin.maps().flags;
  std::vector<char> ranged(g.size(), 0);
  const long nt = g.n_theta, by = kRangeAroundFootprint;
  for (long k = fp.k0 - by; k <= fp.k1 + by; ++k) {
    if (k < 0 || k + 1 >= g.n_z) continue;
    for (long j = fp.j0 - by; j <= fp.j1 + by; ++j) {
      long d = by + 1;  // the distance in cells (Chebyshev) to the footprint, up to by
      for (long dk = -by; dk <= by; ++dk)
        for (long dj = -by; dj <= by; ++dj)
          if (fp.removed(j + dj, k + dk, nt)) d = std::min(d, std::max(std::abs(dj), std::abs(dk)));
      if (d > by || d == 0) continue;
      const int jw = static_cast<int>(wrapped(j, nt)), j1 = static_cast<int>((jw + 1) % nt);
      const int kk = static_cast<int>(k);
      const std::uint8_t corners = flags[g.index(jw, kk)] | flags[g.index(j1, kk)] |
                                   flags[g.index(jw, kk + 1)] | flags[g.index(j1, kk + 1)];
      if (corners & kGrazing) continue;
      undercut[g.index(jw, kk)] = 0;
      if (d < by) ranged[g.index(jw, kk)] = 1;
    }
  }
  return ranged;
}

// The footprint's cells as q = k n_theta + j (j wrapped), sorted.
std::vector<int> footprint_cell_indices(const CylinderGrid& g, const Footprint& fp) {
  std::vector<int> cells;
  for (long k = fp.k0; k <= fp.k1; ++k)
    for (long j = fp.j0; j <= fp.j1; ++j)
      if (fp.cell(j, k))
        cells.push_back(static_cast<int>(k * g.n_theta + wrapped(j, g.n_theta)));
  std::sort(cells.begin(), cells.end());
  cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
  return cells;
}

// The range cells outside the footprint and the undercut cells (`undercut`: grid.size() flags or
// empty), and the caps closing the range mesh's two ends.
void add_range_cells(Builder& b, const PatientModel& model, const Footprint& fp,
                     RangeVertices& range, const std::vector<std::uint8_t>& undercut) {
  const CylinderGrid& g = model.grid();
  const int nt = g.n_theta, nz = g.n_z;
  for (long k = 0; k + 1 < nz; ++k)
    for (long j = 0; j < nt; ++j) {
      if (fp.removed(j, k, nt)) continue;
      if (!undercut.empty() && undercut[g.index(static_cast<int>(j), static_cast<int>(k))]) continue;
      const int v00 = range.at(j, k), v10 = range.at(j + 1, k), v01 = range.at(j, k + 1),
                v11 = range.at(j + 1, k + 1);
      b.tri(v00, v10, v11, SkinPart::Range);
      b.tri(v00, v11, v01, SkinPart::Range);
    }
  for (int end = 0; end < 2; ++end) {
    const int k = end == 0 ? 0 : nz - 1;
    const Eigen::Vector3d c = model.to_lps(0.0, g.z_mm(k), 0.0);
    Eigen::Vector3d color = Eigen::Vector3d::Zero();
    for (int j = 0; j < nt; ++j) color += b.color[range.at(j, k)];
    const int cv = b.add(c, c, color / nt, Eigen::Vector3d::Zero(), {0.0, g.z_mm(k)}, -1);
    b.cap_centres.push_back(cv);
    for (int j = 0; j < nt; ++j) {
      if (end == 0)
        b.tri(cv, range.at(j + 1, k), range.at(j, k), SkinPart::Range);
      else
        b.tri(cv, range.at(j, k), range.at(j + 1, k), SkinPart::Range);
    }
  }
}

// The staircase border of the footprint's cells, counter-clockwise around them, as grid
// vertices (j, k) (j unwrapped).
std::vector<std::pair<long, long>> footprint_border(const Footprint& fp) {
  std::map<std::pair<long, long>, std::pair<long, long>> step;
  for (long k = fp.k0; k <= fp.k1; ++k)
    for (long j = fp.j0; j <= fp.j1; ++j) {
      if (!fp.cell(j, k)) continue;
      auto off = [&](long jj, long kk) { return !fp.in_box(jj, kk) || !fp.cell(jj, kk); };
      if (off(j, k - 1)) step[{j, k}] = {j + 1, k};
      if (off(j + 1, k)) step[{j + 1, k}] = {j + 1, k + 1};
      if (off(j, k + 1)) step[{j + 1, k + 1}] = {j, k + 1};
      if (off(j - 1, k)) step[{j, k + 1}] = {j, k};
    }
  std::vector<std::pair<long, long>> stair;
  auto at = step.begin()->first;
  const auto start = at;
  do {
    stair.push_back(at);
    const auto it = step.find(at);
    if (it == step.end())
      throw Error("render: the footprint's border is not closed (internal error)");
    at = it->second;
  } while (at != start && stair.size() <= step.size());
  return stair;
}

// The drawn skin's isosurface triangles in the undercuts, but those over the mesh's footprint
// and over the cells `ranged` (grid.size() flags) marks as drawn by the range mesh instead.
void add_undercuts(Builder& b, const PatientModel& skin, const DrawnSkin& drawn, const Footprint& fp,
                   const std::vector<char>& ranged, double theta_c) {
  const CylinderGrid& g = skin.grid();
  const TriMesh& iso = drawn.undercuts;
  std::vector<int> index(static_cast<std::size_t>(iso.V.rows()), -1);
  for (Eigen::Index f = 0; f < iso.F.rows(); ++f) {
    const Eigen::Vector3d c =
        (iso.V.row(iso.F(f, 0)) + iso.V.row(iso.F(f, 1)) + iso.V.row(iso.F(f, 2))).transpose() / 3.0;
    const CylindricalPoint cp = skin.to_cylindrical(c);
    const double th = theta_c + wrap180(cp.theta_deg - theta_c);
    const long j = static_cast<long>(std::floor((th - g.theta0_deg) / g.dtheta_deg()));
    const long k = static_cast<long>(std::floor((cp.z_mm - g.z0_mm) / g.dz_mm));
    if (fp.removed(j, k, g.n_theta)) continue;
    if (k >= 0 && k < g.n_z &&
        ranged[g.index(static_cast<int>(wrapped(j, g.n_theta)), static_cast<int>(k))])
      continue;
    int t[3];
    for (int a = 0; a < 3; ++a) {
      int& id = index[static_cast<std::size_t>(iso.F(f, a))];
      if (id < 0) {
        const Eigen::Vector3d p = iso.V.row(iso.F(f, a)).transpose();
        const CylindricalPoint q = skin.to_cylindrical(p);
        id = b.add(p, p, skin_color(skin, q.theta_deg, q.z_mm), Eigen::Vector3d::Zero(),
                   {q.theta_deg, q.z_mm}, -1);
        b.given_normals.emplace_back(id, drawn.undercut_normals.row(iso.F(f, a)).transpose());
      }
      t[a] = id;
    }
    b.tri(t[0], t[1], t[2], SkinPart::Isosurface);
  }
}

// Distance (in the plane) from p to the closed polyline `poly`.
double distance_to_loop(const std::vector<Eigen::Vector2d>& poly, const Eigen::Vector2d& p) {
  double best = 1e300;
  for (std::size_t i = 0; i < poly.size(); ++i) {
    const Eigen::Vector2d& a = poly[i];
    const Eigen::Vector2d ab = poly[(i + 1) % poly.size()] - a;
    const double t = ab.squaredNorm() > 0 ? std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0)
                                          : 0.0;
    best = std::min(best, (a + t * ab - p).norm());
  }
  return best;
}

// Each face's info set to its nesting level in the constraint loops: 0 for the faces reached from
// the infinite face without crossing a constrained edge, and one more for each loop crossed. It is
// found by walking the faces' adjacency, so it is exact whatever the faces' shapes: a point-in-
// polygon test at a face's centroid is not, for a sliver of three nearly collinear vertices has
// its centroid on (or at rounding distance from) a loop.
void mark_nesting_levels(Cdt& cdt) {
  for (auto f = cdt.all_faces_begin(); f != cdt.all_faces_end(); ++f) f->info() = -1;
  std::vector<Cdt::Face_handle> level{cdt.infinite_face()}, next;  // the current level's seeds
  for (int depth = 0; !level.empty(); ++depth) {
    std::vector<Cdt::Face_handle> stack = level;
    while (!stack.empty()) {
      const Cdt::Face_handle f = stack.back();
      stack.pop_back();
      if (f->info() >= 0) continue;
      f->info() = depth;
      for (int i = 0; i < 3; ++i) {
        const Cdt::Face_handle n = f->neighbor(i);
        if (n->info() >= 0) continue;
        (cdt.is_constrained(Cdt::Edge(f, i)) ? next : stack).push_back(n);
      }
    }
    level.swap(next);
    next.clear();
  }
}

// The seam between the micropolygons' rim `P` and the footprint's border `stair`: a constrained
// Delaunay triangulation, in (theta as arc at r_ref_mm, z) mm, of the rim's vertices, the
// border's, and the range vertices of the footprint that lie outside the rim (those closer to the
// rim than a quarter of the finer grid spacing are left out, so no sliver pinches). Rim and
// border are constraints, so each of their edges is a triangle edge: the seam shares every edge
// with the micropolygons or the range cells and cannot crack. The triangles kept are those between
// the two loops, found by the loops they are nested in (mark_nesting_levels), not by where their
// centroids fall: the triangulation's convex hull holds slivers outside the border, along its
// concave staircase, whose centroids lie on it. The grid vertices keep the range image's sampling, so the skin around the patch is
// the range surface itself rather than a strip stretched across it.
void add_seam(Builder& b, const CylinderGrid& g, const std::vector<int>& P, const Footprint& fp,
              const std::vector<std::pair<long, long>>& stair, RangeVertices& range,
              double r_ref_mm) {
  const double mm_per_deg = deg_to_rad(1.0) * r_ref_mm;
  auto to_mm = [&](const Eigen::Vector2d& tz) {
    return Eigen::Vector2d(tz.x() * mm_per_deg, tz.y());
  };
  std::vector<Eigen::Vector2d> rim, border;
  for (int v : P) rim.push_back(to_mm(b.theta_z[v]));
  for (const auto& [j, k] : stair) border.push_back(to_mm(grid_corner(g, j, k)));
  Cdt cdt;
  std::vector<Cdt::Vertex_handle> rim_h, border_h;
  std::size_t n_inserted = 0;
  auto insert = [&](const Eigen::Vector2d& p, int id) {
    const Cdt::Vertex_handle h = cdt.insert(CdtPoint(p.x(), p.y()));
    if (cdt.number_of_vertices() > n_inserted) {
      h->info() = id;
      ++n_inserted;
    }
    return h;
  };
  for (std::size_t i = 0; i < P.size(); ++i) rim_h.push_back(insert(rim[i], P[i]));
  for (std::size_t i = 0; i < stair.size(); ++i)
    border_h.push_back(insert(border[i], range.at(stair[i].first, stair[i].second)));
  const double keep_off_mm = 0.25 * std::min(g.dz_mm, g.dtheta_deg() * mm_per_deg);
  for (long k = fp.k0; k <= fp.k1 + 1; ++k)
    for (long j = fp.j0; j <= fp.j1 + 1; ++j) {
      bool in_fp = false;  // a corner of a removed cell
      for (long dk = -1; dk <= 0 && !in_fp; ++dk)
        for (long dj = -1; dj <= 0 && !in_fp; ++dj)
          in_fp = fp.in_box(j + dj, k + dk) && fp.cell(j + dj, k + dk);
      if (!in_fp) continue;
      const Eigen::Vector2d p = to_mm(grid_corner(g, j, k));
      if (point_in_polygon(rim, p) || distance_to_loop(rim, p) < keep_off_mm) continue;
      insert(p, range.at(j, k));
    }
  for (const auto* loop : {&rim_h, &border_h})
    for (std::size_t i = 0; i < loop->size(); ++i)
      cdt.insert_constraint((*loop)[i], (*loop)[(i + 1) % loop->size()]);
  if (cdt.number_of_vertices() != n_inserted)
    throw Error(cat("render: the seam's rim and border cross (", cdt.number_of_vertices() - n_inserted,
                    " crossings); the mesh's rim is not a simple loop (internal error)"));
  for (const auto* loop : {&rim_h, &border_h})
    for (std::size_t i = 0; i < loop->size(); ++i)
      if (!cdt.is_edge((*loop)[i], (*loop)[(i + 1) % loop->size()]))
        throw Error("render: a vertex of the seam lies on the rim or the border, or two of their "
                    "vertices coincide (internal error)");
  // the border encloses the rim: level 0 outside the border, 1 between the loops, 2 in the rim
  mark_nesting_levels(cdt);
  for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f)
    if (f->info() == 1)
      b.tri(f->vertex(0)->info(), f->vertex(1)->info(), f->vertex(2)->info(), SkinPart::Seam);
}

// normal_pre: the drawn surface's normal field at each vertex's (theta, z) (the end caps' centres:
// their mesh normal); normal_post: normal_pre turned by the change of the mesh's own normal,
// n_post = unit(n_pre + m_post - m_pre), so that it equals normal_pre exactly wherever no vertex
// of the one-ring moved, and follows the deformation elsewhere.
void shade_normals(const PatientModel& skin, const std::vector<int>& cap_centres,
                   const std::vector<std::pair<int, Eigen::Vector3d>>& given, SkinSurfaces& out) {
  const NormalField field(skin);
  const Eigen::MatrixX3d m_pre = vertex_normals(out.pre), m_post = vertex_normals(out.post);
  const auto nv = out.pre.V.rows();
  out.normal_pre.resize(nv, 3);
  out.normal_post.resize(nv, 3);
  std::vector<char> is_cap(static_cast<std::size_t>(nv), 0);
  for (int v : cap_centres) is_cap[static_cast<std::size_t>(v)] = 1;
  for (Eigen::Index v = 0; v < nv; ++v) {
    const bool cap = is_cap[static_cast<std::size_t>(v)];
    const Eigen::Vector3d n = cap ? Eigen::Vector3d(m_pre.row(v)) : field.at(out.theta_z(v, 0), out.theta_z(v, 1));
    out.normal_pre.row(v) = n.transpose();
    const Eigen::Vector3d q = n + (m_post.row(v) - m_pre.row(v)).transpose();
    out.normal_post.row(v) = (q.norm() > 0 ? q.normalized() : n).transpose();
  }
  for (const auto& [v, n] : given) out.normal_pre.row(v) = out.normal_post.row(v) = n.transpose();
}

// A closure in the whole face (closure/face_domain.hpp) moves the skin beyond the patch too:
// the vertices of the range mesh, the seam and the undercuts follow the tissue model's skin
// nodes (the mesh's node set closure::kFaceSkinNodes) by inverse-distance-squared weights, and
// within kSeamBlendMm of the patch's rim its rim's displacement (seam_field()); the
// micropolygons (the first n_micro vertices) carry the patch's own displacement.
void move_with_face(const fem::Mesh& mesh, const Eigen::MatrixX3d& u, int n_micro, SkinSurfaces& out) {
  if (!mesh.node_sets.count(closure::kFaceSkinNodes)) return;
  const DisplacementAt field =
      seam_field(out, out.post.V - out.pre.V, closure::skin_displacement(mesh, u));
  for (Eigen::Index v = n_micro; v < out.pre.V.rows(); ++v)
    if (const auto d = field(out.pre.V.row(v).transpose())) out.post.V.row(v) += d->transpose();
}

void pack(Builder& b, SkinSurfaces& out) {
  const auto nv = static_cast<Eigen::Index>(b.pre.size());
  out.pre.V.resize(nv, 3);
  out.post.V.resize(nv, 3);
  out.color.resize(nv, 3);
  out.range_offset_mm.resize(nv, 3);
  out.theta_z.resize(nv, 2);
  out.vertex_element.resize(nv);
  out.vertex_natural.resize(nv, 2);
  for (Eigen::Index v = 0; v < nv; ++v) {
    out.pre.V.row(v) = b.pre[v];
    out.post.V.row(v) = b.post[v];
    out.color.row(v) = b.color[v];
    out.range_offset_mm.row(v) = b.offset[v];
    out.theta_z.row(v) = b.theta_z[v];
    out.vertex_element[v] = b.element[v];
    out.vertex_natural.row(v) = b.natural[v];
  }
  out.pre.F.resize(static_cast<Eigen::Index>(b.faces.size()), 3);
  for (std::size_t f = 0; f < b.faces.size(); ++f)
    out.pre.F.row(static_cast<Eigen::Index>(f)) = b.faces[f];
  out.post.F = out.pre.F;
  out.face_part = std::move(b.part);
}

}  // namespace

SkinSurfaces displaced_skin(const PatientModel& model, const fem::Mesh& mesh,
                            const Eigen::MatrixX3d* displacement_mm, int n_subdivisions,
                            const DrawnSkin* drawn, SkinExtent extent) {
  check_skin_inputs(mesh, displacement_mm, n_subdivisions);
  const PatientModel& skin = drawn ? drawn->range : model;
  if (skin.grid().n_theta != model.grid().n_theta || skin.grid().n_z != model.grid().n_z ||
      skin.grid().theta0_deg != model.grid().theta0_deg || skin.grid().z0_mm != model.grid().z0_mm ||
      skin.grid().dz_mm != model.grid().dz_mm)
    throw InvalidInput("render: the drawn skin's grid is not the model's; build it with "
                       "drawn_skin() from this model");
  SkinSurfaces out;
  out.skin_elements = skin_elements(model, mesh);
  const Eigen::Vector3d centre = top_face_centre(mesh, out.skin_elements);
  out.mesh_centre_lps = centre;
  const double theta_c = model.to_cylindrical(centre).theta_deg;

  // Micropolygons, welded along element edges.
  Builder b;
  std::map<std::array<long, 3>, int> welded;
  for (int e : out.skin_elements)
    FaceSampler(b, welded, model, skin, mesh, displacement_mm, e, n_subdivisions, theta_c)
        .add_triangles();
  const int n_micro = static_cast<int>(b.pre.size());
  out.n_micropolygon_vertices = n_micro;
  for (int v = 0; v < n_micro; ++v)
    out.mesh_radius_mm = std::max(out.mesh_radius_mm, (b.pre[v] - centre).norm());

  const std::vector<std::vector<int>> loops = border_loops(b.faces);
  const int rim = outer_rim(b, loops);
  add_wound_fills(b, loops, rim);

  // The range mesh around the micropolygons, stitched to their rim.
  const bool whole = extent == SkinExtent::WholeHead;
  RangeVertices range(b, skin, whole);
  const Footprint fp = footprint_cells(model.grid(), loop_theta_z(b, loops[rim]));
  out.replaced_cells = footprint_cell_indices(model.grid(), fp);
  if (whole) {
    std::vector<std::uint8_t> undercut = drawn ? drawn->undercut_cells : std::vector<std::uint8_t>{};
    const std::vector<char> ranged =
        undercut.empty() ? std::vector<char>(skin.grid().size(), 0)
                         : range_around_footprint(skin, fp, undercut);
    add_range_cells(b, skin, fp, range, undercut);
    if (drawn) add_undercuts(b, skin, *drawn, fp, ranged, theta_c);
  }
  // The planner's part (SkinExtent::Patch) stays the patch and its seam; the page moves its own
  // range mesh around them with the same face field (the server's skin_moved.bin), so the
  // seam's range vertices move here as there.
  const double r_ref = skin.r_skin(theta_c, model.to_cylindrical(centre).z_mm);
  add_seam(b, model.grid(), loops[rim], fp, footprint_border(fp), range, r_ref);

  const std::vector<int> cap_centres = b.cap_centres;
  const auto given_normals = b.given_normals;
  pack(b, out);
  out.rim_vertices = loops[rim];
  if (displacement_mm) move_with_face(mesh, *displacement_mm, n_micro, out);
  shade_normals(skin, cap_centres, given_normals, out);
  return out;
}

Eigen::MatrixX3d skin_normal_field(const PatientModel& skin, const Eigen::MatrixX2d& theta_z) {
  const NormalField field(skin);
  Eigen::MatrixX3d N(theta_z.rows(), 3);
  for (Eigen::Index i = 0; i < theta_z.rows(); ++i)
    N.row(i) = field.at(theta_z(i, 0), theta_z(i, 1)).transpose();
  return N;
}

DisplacementAt seam_field(const SkinSurfaces& skin, const Eigen::MatrixX3d& values,
                          DisplacementAt far) {
  if (values.rows() != skin.pre.V.rows())
    throw InvalidInput(cat("seam_field: ", values.rows(), " values for ", skin.pre.V.rows(),
                           " skin vertices"));
  if (skin.rim_vertices.empty()) return far;
  const auto n = static_cast<Eigen::Index>(skin.rim_vertices.size());
  Eigen::MatrixX3d points(n, 3), at_rim(n, 3);
  for (Eigen::Index i = 0; i < n; ++i) {
    points.row(i) = skin.pre.V.row(skin.rim_vertices[static_cast<std::size_t>(i)]);
    at_rim.row(i) = values.row(skin.rim_vertices[static_cast<std::size_t>(i)]);
  }
  return blend_across_seam(std::move(far), points, at_rim, kSeamBlendMm);
}

Eigen::VectorXd nodal_field_on_skin(const SkinSurfaces& skin, const fem::Mesh& mesh,
                                    const Eigen::VectorXd& nodal, double off_mesh_value) {
  if (nodal.size() != mesh.n_nodes())
    throw InvalidInput(cat("render: the nodal field has ", nodal.size(), " values but the mesh has ",
                           mesh.n_nodes(), " nodes"));
  if (!nodal.allFinite()) throw InvalidInput("render: the nodal field has non-finite values");
  const auto nv = skin.pre.V.rows();
  Eigen::VectorXd out = Eigen::VectorXd::Constant(nv, off_mesh_value);
  Eigen::VectorXd N;
  Eigen::MatrixX3d dN;
  for (Eigen::Index v = 0; v < nv; ++v) {
    const int e = skin.vertex_element[v];
    if (e < 0) continue;
    if (e >= static_cast<int>(mesh.elements.size()))
      throw InvalidInput(cat("render: skin vertex ", v, " comes from element ", e, " but the mesh has ",
                             mesh.elements.size(), "; was the skin built from this mesh?"));
    const fem::Element& el = mesh.elements[static_cast<std::size_t>(e)];
    const Eigen::Vector3d xi(skin.vertex_natural(v, 0), skin.vertex_natural(v, 1), -1.0);
    fem::shape_functions(el.type, xi, N, dN);
    double f = 0;
    for (int a = 0; a < el.n_nodes(); ++a) f += N[a] * nodal[el.nodes[a]];
    out[v] = f;
  }
  // A closure in the whole face: the skin around the patch (the range mesh, the seam, the
  // undercuts, as move_with_face() moves them) takes the field of the tissue model's skin nodes,
  // so the map goes on across the patch's rim. A wound fill's own vertices keep off_mesh_value.
  if (mesh.node_sets.count(closure::kFaceSkinNodes)) {
    const auto field = closure::skin_scalar(mesh, nodal);
    // The patch's own field at its rim is the least accurate of it (the tie's kinks in the
    // outermost elements: a ring of teeth on the map), so within kSeamBlendInsideMm of the rim
    // it goes over into the tissue's, and the two meet there without an edge. The closeness to
    // the rim, 1 - d / width, is blend_across_seam() of ones on the rim into nothing.
    if (!skin.rim_vertices.empty()) {
      const auto n_rim = static_cast<Eigen::Index>(skin.rim_vertices.size());
      Eigen::MatrixX3d rim(n_rim, 3);
      for (Eigen::Index i = 0; i < n_rim; ++i)
        rim.row(i) = skin.pre.V.row(skin.rim_vertices[static_cast<std::size_t>(i)]);
      const DisplacementAt closeness = blend_across_seam(
          [](const Eigen::Vector3d&) { return std::optional<Eigen::Vector3d>(); }, rim,
          Eigen::MatrixX3d::Ones(n_rim, 3), kSeamBlendInsideMm);
      for (Eigen::Index v = 0; v < skin.n_micropolygon_vertices; ++v) {
        if (skin.vertex_element[v] < 0) continue;
        const Eigen::Vector3d x = skin.pre.V.row(v).transpose();
        const auto c = closeness(x);
        if (!c) continue;
        if (const auto f = field(x)) out[v] = c->x() * *f + (1 - c->x()) * out[v];
      }
    }
    std::vector<char> on_skin(static_cast<std::size_t>(nv), 0);
    for (Eigen::Index f = 0; f < skin.pre.F.rows(); ++f)
      if (skin.face_part[static_cast<std::size_t>(f)] != SkinPart::WoundFill)
        for (int c = 0; c < 3; ++c) on_skin[static_cast<std::size_t>(skin.pre.F(f, c))] = 1;
    for (Eigen::Index v = skin.n_micropolygon_vertices; v < nv; ++v)
      if (skin.vertex_element[v] < 0 && on_skin[static_cast<std::size_t>(v)])
        if (const auto f = field(skin.pre.V.row(v).transpose())) out[v] = *f;
  }
  return out;
}

}  // namespace caps::render

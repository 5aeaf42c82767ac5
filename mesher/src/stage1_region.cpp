#include "stage1_region.hpp"

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Delaunay_mesh_face_base_2.h>
#include <CGAL/Delaunay_mesh_size_criteria_2.h>
#include <CGAL/Delaunay_mesh_vertex_base_2.h>
#include <CGAL/Delaunay_mesher_no_edge_refinement_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <cmath>
#include <deque>
#include <map>
#include <numbers>

namespace caps::mesher::detail {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Delaunay_mesh_vertex_base_2<K>;
using Fb = CGAL::Delaunay_mesh_face_base_2<K>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<K, Tds, CGAL::Exact_predicates_tag>;
using Criteria = CGAL::Delaunay_mesh_size_criteria_2<Cdt>;
using Mesher = CGAL::Delaunay_mesher_no_edge_refinement_2<Cdt, Criteria>;

/// In-domain marks by nesting parity across constrained edges (CGAL's polygon_triangulation
/// example): a face is inside when an odd number of constraints separate it from infinity.
void mark_by_nesting(Cdt& cdt) {
  std::map<Cdt::Face_handle, int> level{{cdt.infinite_face(), 0}};
  std::deque<Cdt::Face_handle> queue{cdt.infinite_face()};
  while (!queue.empty()) {  // 0-1 breadth-first: crossing a constraint costs 1
    const auto f = queue.front();
    queue.pop_front();
    for (int i = 0; i < 3; ++i) {
      const auto g = f->neighbor(i);
      const int step = cdt.is_constrained({f, i}) ? 1 : 0, lg = level[f] + step;
      const auto it = level.find(g);
      if (it != level.end() && it->second <= lg) continue;
      level[g] = lg;
      if (step)
        queue.push_back(g);
      else
        queue.push_front(g);
    }
  }
  for (auto f = cdt.all_faces_begin(); f != cdt.all_faces_end(); ++f)
    f->set_in_domain(!cdt.is_infinite(f) && level[f] % 2 == 1);
}

}  // namespace

RegionTriangulation triangulate_region(const std::vector<Eigen::Vector2d>& P,
                                       const std::vector<std::array<int, 2>>& boundary,
                                       double size_mm, double min_angle_deg) {
  Cdt cdt;
  std::map<int, Cdt::Vertex_handle> handle;
  std::map<Cdt::Vertex_handle, int> id;
  for (const auto& e : boundary)
    for (int v : e)
      if (!handle.count(v)) {
        const auto h = cdt.insert(K::Point_2(P[v].x(), P[v].y()));
        if (id.count(h)) return {};  // two region points coincide (twins)
        handle[v] = h;
        id[h] = v;
      }
  for (const auto& e : boundary) cdt.insert_constraint(handle[e[0]], handle[e[1]]);
  if (static_cast<int>(cdt.number_of_vertices()) != static_cast<int>(handle.size())) return {};
  mark_by_nesting(cdt);

  const double s = std::sin(std::min(min_angle_deg, 20.7) * std::numbers::pi / 180);
  Mesher mesher(cdt, Criteria(s * s, size_mm));
  mesher.init(true);
  mesher.refine_mesh();

  RegionTriangulation out;
  const int n = static_cast<int>(P.size());
  for (auto v = cdt.finite_vertices_begin(); v != cdt.finite_vertices_end(); ++v)
    if (!id.count(v)) {
      id[v] = n + static_cast<int>(out.new_points.size());
      out.new_points.emplace_back(v->point().x(), v->point().y());
    }
  std::size_t n_constrained = 0;
  for (auto e = cdt.finite_edges_begin(); e != cdt.finite_edges_end(); ++e)
    if (cdt.is_constrained(*e)) {
      ++n_constrained;
      // a boundary edge split or ending at a new point: the region's border would change
      if (id.at(e->first->vertex(Cdt::cw(e->second))) >= n ||
          id.at(e->first->vertex(Cdt::ccw(e->second))) >= n)
        return {};
    }
  if (n_constrained != boundary.size()) return {};
  for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f)
    if (f->is_in_domain())
      out.triangles.push_back({id.at(f->vertex(0)), id.at(f->vertex(1)), id.at(f->vertex(2))});
  // New points only inside the region (an outside point would be a vertex of no polygon).
  std::vector<int> used(out.new_points.size(), 0);
  for (const auto& t : out.triangles)
    for (int v : t)
      if (v >= n) used[v - n] = 1;
  for (int u : used)
    if (!u) return {};
  return out;
}

}  // namespace caps::mesher::detail

#include "tissue_mesh_3.hpp"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Image_3.h>
#include <CGAL/Labeled_mesh_domain_3.h>
#include <CGAL/Mesh_complex_3_in_triangulation_3.h>
#include <CGAL/Mesh_criteria_3.h>
#include <CGAL/Mesh_triangulation_3.h>
#include <CGAL/exude_mesh_3.h>
#include <CGAL/make_mesh_3.h>

#include <cstring>
#include <unordered_map>

#include "caps/core/error.hpp"

namespace caps::mesher::detail {

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Domain = CGAL::Labeled_mesh_domain_3<K>;
#ifdef CAPS_TISSUE_PARALLEL_MESH_3
using Concurrency = CGAL::Parallel_tag;
#else
using Concurrency = CGAL::Sequential_tag;
#endif
using Tr = CGAL::Mesh_triangulation_3<Domain, CGAL::Default, Concurrency>::type;
using C3t3 = CGAL::Mesh_complex_3_in_triangulation_3<Tr>;
using Mesh_criteria = CGAL::Mesh_criteria_3<Tr>;
using Point = K::Point_3;
using FT = K::FT;

// A size criterion from a function of the point (Mesh_3's sizing-field concept).
struct SizeField {
  const std::function<double(const Eigen::Vector3d&)>* f;
  FT operator()(const Point& p, const int, const Domain::Index&) const {
    return (*f)(Eigen::Vector3d(p.x(), p.y(), p.z()));
  }
};

}  // namespace

Mesh3Output mesh_label_image(const LabelImage& image, const Mesh3Criteria& criteria,
                             Reporter* reporter) {
  const Eigen::Vector3i& d = image.dims;
  const std::size_t n = static_cast<std::size_t>(d[0]) * d[1] * d[2];
  if (d.minCoeff() < 2 || image.labels.size() != n)
    throw InvalidInput("tissue model: the label image is empty or mis-sized");
  _image* im = _createImage(d[0], d[1], d[2], 1, image.spacing_mm[0], image.spacing_mm[1],
                            image.spacing_mm[2], 1, WK_FIXED, SGN_UNSIGNED);
  if (!im) throw InvalidInput("tissue model: cannot allocate the label image");
  std::memcpy(im->data, image.labels.data(), n);
  CGAL::Image_3 cimage(im);  // owns im
  Domain domain = Domain::create_labeled_image_mesh_domain(
      cimage, CGAL::parameters::relative_error_bound = 1e-6);

  SizeField facet_size{&criteria.facet_size_mm}, facet_distance{&criteria.facet_distance_mm},
      cell_size{&criteria.cell_size_mm};
  Mesh_criteria mesh_criteria(
      CGAL::parameters::facet_angle = criteria.facet_angle_deg,
      CGAL::parameters::facet_size = facet_size, CGAL::parameters::facet_distance = facet_distance,
      CGAL::parameters::cell_radius_edge_ratio = criteria.cell_radius_edge_ratio,
      CGAL::parameters::cell_size = cell_size);

  // Initial points on the boundary: where a labelled voxel meets an unlabelled neighbour along
  // i, j or k, the domain's own intersection of the segment between their centres. Spread
  // evenly over all such pairs (a stride), so every component of the tissue is seeded.
  std::vector<std::pair<std::size_t, int>> pairs;
  for (int k = 0; k < d[2]; ++k)
    for (int j = 0; j < d[1]; ++j)
      for (int i = 0; i < d[0]; ++i) {
        const std::size_t a = (static_cast<std::size_t>(k) * d[1] + j) * d[0] + i;
        if (!image.labels[a]) continue;
        if (i + 1 < d[0] && !image.labels[a + 1]) pairs.push_back({a, 0});
        if (j + 1 < d[1] && !image.labels[a + d[0]]) pairs.push_back({a, 1});
        if (k + 1 < d[2] && !image.labels[a + static_cast<std::size_t>(d[0]) * d[1]])
          pairs.push_back({a, 2});
      }
  if (pairs.empty()) throw InvalidInput("tissue model: the label image has no boundary");
  C3t3 c3t3;
  Tr& tr = c3t3.triangulation();
  const auto construct_intersection = domain.construct_intersection_object();
  const auto cwp = tr.geom_traits().construct_weighted_point_3_object();
  const std::size_t stride = std::max<std::size_t>(
      1, pairs.size() / static_cast<std::size_t>(std::max(1, criteria.max_seeds)));
  for (std::size_t s = 0; s < pairs.size(); s += stride) {
    const std::size_t a = pairs[s].first;
    const int axis = pairs[s].second;
    const int i = static_cast<int>(a % d[0]);
    const int j = static_cast<int>((a / d[0]) % d[1]);
    const int k = static_cast<int>(a / (static_cast<std::size_t>(d[0]) * d[1]));
    Eigen::Vector3d p0(i * image.spacing_mm[0], j * image.spacing_mm[1], k * image.spacing_mm[2]);
    Eigen::Vector3d p1 = p0;
    p1[axis] += image.spacing_mm[axis];
    const auto hit = construct_intersection(
        K::Segment_3(Point(p0[0], p0[1], p0[2]), Point(p1[0], p1[1], p1[2])));
    if (std::get<2>(hit) == 0) continue;
    const auto v = tr.insert(cwp(std::get<0>(hit)));
    if (v == Tr::Vertex_handle()) continue;
    c3t3.set_dimension(v, 2);
    c3t3.set_index(v, std::get<1>(hit));
  }
  if (reporter) reporter->check_cancelled();
  CGAL::refine_mesh_3(c3t3, domain, mesh_criteria, CGAL::parameters::no_perturb(),
                      CGAL::parameters::no_exude(), CGAL::parameters::no_lloyd(),
                      CGAL::parameters::no_odt());
  // Sliver exudation (weights on the vertices, the connectivity changed, no point moved) within
  // a time budget: cheap beside the refinement, and it removes most slivers a solver would
  // suffer from.
  if (criteria.exude_seconds > 0)
    CGAL::exude_mesh_3(c3t3, CGAL::parameters::time_limit = criteria.exude_seconds,
                       CGAL::parameters::sliver_bound = criteria.exude_sliver_bound_deg);

  Mesh3Output out;
  std::unordered_map<Tr::Vertex_handle, int> id;
  std::vector<Eigen::Vector3d> nodes;
  auto node = [&](Tr::Vertex_handle v) {
    auto [it, inserted] = id.emplace(v, static_cast<int>(nodes.size()));
    if (inserted) {
      const auto& p = tr.point(v);
      nodes.emplace_back(CGAL::to_double(p.x()), CGAL::to_double(p.y()), CGAL::to_double(p.z()));
    }
    return it->second;
  };
  std::vector<Eigen::Vector4i> tets;
  tets.reserve(c3t3.number_of_cells_in_complex());
  for (auto c = c3t3.cells_in_complex_begin(); c != c3t3.cells_in_complex_end(); ++c) {
    Eigen::Vector4i t(node(c->vertex(0)), node(c->vertex(1)), node(c->vertex(2)),
                      node(c->vertex(3)));
    tets.push_back(t);
  }
  std::vector<Eigen::Vector3i> faces;
  for (auto f = c3t3.facets_in_complex_begin(); f != c3t3.facets_in_complex_end(); ++f) {
    const auto cell = f->first;
    const int opposite = f->second;
    Eigen::Vector3i t;
    int m = 0;
    for (int q = 0; q < 4; ++q)
      if (q != opposite) t[m++] = node(cell->vertex(q));
    faces.push_back(t);
  }
  out.nodes.resize(static_cast<Eigen::Index>(nodes.size()), 3);
  for (std::size_t v = 0; v < nodes.size(); ++v)
    out.nodes.row(static_cast<Eigen::Index>(v)) = nodes[v];
  out.tets.resize(static_cast<Eigen::Index>(tets.size()), 4);
  for (std::size_t t = 0; t < tets.size(); ++t) {
    Eigen::Vector4i c = tets[t];
    const Eigen::Vector3d x0 = nodes[c[0]];
    const double vol = (nodes[c[1]] - x0).cross(nodes[c[2]] - x0).dot(nodes[c[3]] - x0);
    if (vol < 0) std::swap(c[2], c[3]);
    out.tets.row(static_cast<Eigen::Index>(t)) = c.transpose();
  }
  out.boundary_faces.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (std::size_t f = 0; f < faces.size(); ++f)
    out.boundary_faces.row(static_cast<Eigen::Index>(f)) = faces[f].transpose();
  return out;
}

}  // namespace caps::mesher::detail

#include "caps/closure/suture_spacing.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <utility>

#include "caps/core/error.hpp"

namespace caps::closure {

using namespace caps::fem;
using namespace caps::mesher;

namespace {

// The skin node of node n's column: up the column (the same (theta, z), a lower level) through
// the elements n belongs to, to level 0. A column is not found by its (theta, z) alone: the two
// lips of a cut have columns at the same (theta, z), and a Z's lips are sewn to different places.
int column_skin_node(const ContinuumMesh& cm, const std::vector<std::vector<int>>& elements_of,
                     int n) {
  const Mesh& mesh = cm.mesh;
  while (cm.node_level[n] > 0) {
    int up = -1;
    for (int e : elements_of[static_cast<std::size_t>(n)]) {
      const Element& el = mesh.elements[static_cast<std::size_t>(e)];
      for (int k = 0; k < el.n_nodes(); ++k)
        if (const int m = el.nodes[static_cast<std::size_t>(k)];
            cm.node_theta_z.row(m) == cm.node_theta_z.row(n) &&
            cm.node_level[m] < cm.node_level[n] && (up < 0 || cm.node_level[m] < cm.node_level[up]))
          up = m;
    }
    if (up < 0) break;  // not a column of the continuum mesher: the node itself
    n = up;
  }
  return n;
}

// The closed skin sites: for each suture pair, the deformed position of the skin node of its
// first node's column.
std::vector<Eigen::Vector3d> pair_sites(const ContinuumMesh& cm, const Eigen::MatrixX3d& u) {
  const Mesh& mesh = cm.mesh;
  std::vector<std::vector<int>> elements_of(static_cast<std::size_t>(mesh.n_nodes()));
  for (std::size_t e = 0; e < mesh.elements.size(); ++e)
    for (int k = 0; k < mesh.elements[e].n_nodes(); ++k)
      elements_of[static_cast<std::size_t>(mesh.elements[e].nodes[static_cast<std::size_t>(k)])]
          .push_back(static_cast<int>(e));
  std::vector<Eigen::Vector3d> site;
  for (const auto& s : mesh.sutures) {
    const int n = column_skin_node(cm, elements_of, s.a);
    site.push_back(mesh.nodes.row(n).transpose() + u.row(n).transpose());
  }
  return site;
}

// The length of the minimum spanning tree of the points (Prim, O(n^2)).
double spanning_tree_length(const std::vector<Eigen::Vector3d>& p) {
  const std::size_t n = p.size();
  if (n < 2) return 0;
  std::vector<double> best(n, std::numeric_limits<double>::infinity());
  std::vector<char> in(n, 0);
  double total = 0;
  std::size_t cur = 0;
  in[0] = 1;
  for (std::size_t k = 1; k < n; ++k) {
    std::size_t next = n;
    for (std::size_t i = 0; i < n; ++i) {
      if (in[i]) continue;
      best[i] = std::min(best[i], (p[i] - p[cur]).norm());
      if (next == n || best[i] < best[next]) next = i;
    }
    total += best[next];
    in[next] = 1;
    cur = next;
  }
  return total;
}

}  // namespace

SutureSpacing suture_spacing(const ContinuumMesh& cm, const SolveResult& r, double spacing_mm) {
  if (!(spacing_mm > 0) || !std::isfinite(spacing_mm))
    throw InvalidInput(cat("suture spacing ", spacing_mm, " mm must be > 0 (e.g. 5 mm)"));
  const Mesh& mesh = cm.mesh;
  if (r.displacement_mm.rows() != mesh.n_nodes() || r.suture_forces.size() != mesh.sutures.size())
    throw InvalidInput(cat("suture spacing: the result (", r.displacement_mm.rows(), " nodes, ",
                           r.suture_forces.size(), " suture forces) is not a solve of this mesh (",
                           mesh.n_nodes(), " nodes, ", mesh.sutures.size(), " suture pairs)"));
  SutureSpacing out;
  out.spacing_mm = spacing_mm;
  if (mesh.sutures.empty()) return out;
  const std::vector<Eigen::Vector3d> site = pair_sites(cm, r.displacement_mm);
  // Each pair's closing force: its force on a along the gap it closes (x_b - x_a).
  std::vector<double> closing(mesh.sutures.size(), 0.0);
  for (std::size_t k = 0; k < mesh.sutures.size(); ++k) {
    const auto& s = mesh.sutures[k];
    const Eigen::Vector3d gap = (mesh.nodes.row(s.b) - mesh.nodes.row(s.a)).transpose();
    if (gap.norm() > 0) closing[k] = r.suture_forces[k].force_on_a_n.dot(gap.normalized());
  }
  // The distinct skin sites, the wound's length over them.
  std::vector<Eigen::Vector3d> sites;
  for (const auto& p : site) {
    bool seen = false;
    for (const auto& q : sites) seen |= (p - q).norm() < 1e-6;
    if (!seen) sites.push_back(p);
  }
  out.wound_length_mm = spanning_tree_length(sites);
  // Sutures spacing_mm apart: the first where one suture would hold the most (the site whose
  // pairs within half a spacing close with the largest force in sum), then each next one at the
  // uncovered site nearest to those placed (an advancing front along the wound's lines both
  // ways, branches included); every pair then goes to its nearest suture. So the row has a
  // suture at the wound's most loaded place, wherever the loop starts and whichever way it
  // runs (a design and its mirror image get the same largest suture); started at an end, the
  // row's phase decided the largest suture by up to a third.
  std::size_t first = 0;
  double most = -std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < sites.size(); ++i) {
    double held = 0;
    for (std::size_t k = 0; k < site.size(); ++k)
      if ((site[k] - sites[i]).norm() <= 0.5 * spacing_mm) held += closing[k];
    if (held > most * (1 + 1e-9) + 1e-12) {
      most = held;
      first = i;
    }
  }
  std::vector<Eigen::Vector3d> centres{sites[first]};
  std::vector<double> nearest(sites.size(), std::numeric_limits<double>::infinity());
  for (;;) {
    const Eigen::Vector3d& c = centres.back();
    for (std::size_t i = 0; i < sites.size(); ++i) nearest[i] = std::min(nearest[i], (sites[i] - c).norm());
    std::size_t next = sites.size();
    for (std::size_t i = 0; i < sites.size(); ++i)
      if (nearest[i] >= spacing_mm * (1 - 1e-9) && (next == sites.size() || nearest[i] < nearest[next]))
        next = i;
    if (next == sites.size()) break;
    centres.push_back(sites[next]);
  }
  std::vector<SutureStitch> row(centres.size());
  for (std::size_t c = 0; c < centres.size(); ++c) row[c].position_mm = centres[c];
  for (std::size_t k = 0; k < site.size(); ++k) {
    std::size_t best = 0;
    for (std::size_t c = 1; c < centres.size(); ++c)
      if ((site[k] - centres[c]).norm() < (site[k] - centres[best]).norm()) best = c;
    row[best].force_n += closing[k];
    row[best].n_pairs += 1;
  }
  // A suture cannot push: one whose pairs push the lips apart in sum is reported apart, in no
  // total (the tissue there is pressed together; contact, not the suture, carries it).
  for (const SutureStitch& s : row) {
    if (s.force_n < 0) {
      out.compressive.push_back(s);
      out.compressive_force_n += s.force_n;
      continue;
    }
    out.sutures.push_back(s);
    out.total_force_n += s.force_n;
    out.max_suture_force_n = std::max(out.max_suture_force_n, s.force_n);
  }
  if (!out.sutures.empty())
    out.mean_suture_force_n = out.total_force_n / static_cast<double>(out.sutures.size());
  out.force_per_mm_n = out.wound_length_mm > 0 ? out.total_force_n / out.wound_length_mm : 0.0;
  return out;
}

}  // namespace caps::closure

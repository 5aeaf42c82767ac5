#include "assemble.hpp"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <limits>
#include <string>


#include "caps/core/error.hpp"
#include "caps/fem/elements.hpp"
#include "elements_impl.hpp"

namespace caps::fem::detail {
namespace {

// Compressed rows: row r is items[start[r] .. start[r+1]).
struct Csr {
  std::vector<int> start, items;
};

// The distinct blocks of one element's nodes; returns how many.
int element_blocks(const Element& el, const DofMap& map, int* out) {
  int k = 0;
  for (int a = 0; a < el.n_nodes(); ++a) {
    const int b = map.node_block[el.nodes[a]];
    if (b >= 0 && std::find(out, out + k, b) == out + k) out[k++] = b;
  }
  return k;
}

// Block -> elements touching it, each element once, in increasing order.
Csr block_elements(const Mesh& mesh, const DofMap& map, int n_blocks) {
  Csr c;
  c.start.assign(n_blocks + 1, 0);
  int blocks[20];
  for (const Element& el : mesh.elements) {
    const int k = element_blocks(el, map, blocks);
    for (int i = 0; i < k; ++i) ++c.start[blocks[i] + 1];
  }
  for (int b = 0; b < n_blocks; ++b) c.start[b + 1] += c.start[b];
  c.items.resize(c.start[n_blocks]);
  std::vector<int> fill(c.start.begin(), c.start.end() - 1);
  for (int e = 0; e < static_cast<int>(mesh.elements.size()); ++e) {
    const int k = element_blocks(mesh.elements[e], map, blocks);
    for (int i = 0; i < k; ++i) c.items[fill[blocks[i]]++] = e;
  }
  return c;
}

// Greedy colouring: each element takes the smallest colour no element sharing a block has.
Csr colour_elements(const Mesh& mesh, const DofMap& map, const Csr& by_block) {
  const int n_el = static_cast<int>(mesh.elements.size());
  std::vector<int> colour(n_el, -1), seen;  // seen[c] == e: colour c is taken near element e
  int n_colours = 0, blocks[20];
  for (int e = 0; e < n_el; ++e) {
    const int k = element_blocks(mesh.elements[e], map, blocks);
    for (int i = 0; i < k; ++i)
      for (int j = by_block.start[blocks[i]]; j < by_block.start[blocks[i] + 1]; ++j)
        if (const int c = colour[by_block.items[j]]; c >= 0) seen[c] = e;
    int c = 0;
    while (c < n_colours && seen[c] == e) ++c;
    if (c == n_colours) {
      ++n_colours;
      seen.push_back(-1);
    }
    colour[e] = c;
  }
  Csr out;
  out.start.assign(n_colours + 1, 0);
  for (int e = 0; e < n_el; ++e) ++out.start[colour[e] + 1];
  for (int c = 0; c < n_colours; ++c) out.start[c + 1] += out.start[c];
  out.items.resize(n_el);
  std::vector<int> fill(out.start.begin(), out.start.end() - 1);
  for (int e = 0; e < n_el; ++e) out.items[fill[colour[e]]++] = e;
  return out;
}

// The distinct blocks of a tie's slave and masters.
void tie_blocks(const TiedNode& t, const DofMap& map, std::vector<int>& out) {
  out.clear();
  for (std::size_t a = 0; a <= t.masters.size(); ++a) {
    const int b = map.node_block[a == 0 ? t.node : t.masters[a - 1]];
    if (b >= 0 && std::find(out.begin(), out.end(), b) == out.end()) out.push_back(b);
  }
}

// Block -> ties touching it (their penalty couples the slave's block to the masters').
Csr block_ties(const Mesh& mesh, const DofMap& map, int n_blocks) {
  Csr c;
  c.start.assign(n_blocks + 1, 0);
  std::vector<int> blocks;
  for (const TiedNode& t : mesh.ties) {
    tie_blocks(t, map, blocks);
    for (int b : blocks) ++c.start[b + 1];
  }
  for (int b = 0; b < n_blocks; ++b) c.start[b + 1] += c.start[b];
  c.items.resize(c.start[n_blocks]);
  std::vector<int> fill(c.start.begin(), c.start.end() - 1);
  for (int i = 0; i < static_cast<int>(mesh.ties.size()); ++i) {
    tie_blocks(mesh.ties[i], map, blocks);
    for (int b : blocks) c.items[fill[b]++] = i;
  }
  return c;
}

}  // namespace

Assembly assemble_structure(const Mesh& mesh, const DofMap& map) {
  const int n = map.n_eq;
  const int n_blocks = static_cast<int>(map.block_start.size()) - 1;
  const Csr by_block = block_elements(mesh, map, n_blocks);
  const Csr ties_by_block = block_ties(mesh, map, n_blocks);
  Assembly out;

  // Block pattern: column block B couples to the blocks B' <= B of the elements touching it.
  std::vector<std::vector<int>> cols(n_blocks);
  tbb::enumerable_thread_specific<std::vector<int>> marks(
      [n_blocks] { return std::vector<int>(n_blocks, -1); });
  tbb::parallel_for(tbb::blocked_range<int>(0, n_blocks, 256), [&](const tbb::blocked_range<int>& r) {
    auto& mark = marks.local();
    int blocks[20];
    std::vector<int> tied;
    for (int B = r.begin(); B < r.end(); ++B) {
      auto& c = cols[B];
      for (int k = by_block.start[B]; k < by_block.start[B + 1]; ++k) {
        const int m = element_blocks(mesh.elements[by_block.items[k]], map, blocks);
        for (int i = 0; i < m; ++i)
          if (blocks[i] <= B && mark[blocks[i]] != B) {
            mark[blocks[i]] = B;
            c.push_back(blocks[i]);
          }
      }
      for (int k = ties_by_block.start[B]; k < ties_by_block.start[B + 1]; ++k) {
        tie_blocks(mesh.ties[ties_by_block.items[k]], map, tied);
        for (int b : tied)
          if (b <= B && mark[b] != B) {
            mark[b] = B;
            c.push_back(b);
          }
      }
      std::sort(c.begin(), c.end());
    }
  });
  out.nbr_start.assign(n_blocks + 1, 0);
  for (int B = 0; B < n_blocks; ++B)
    out.nbr_start[B + 1] = out.nbr_start[B] + static_cast<int>(cols[B].size());
  out.nbr.resize(out.nbr_start[n_blocks]);
  out.nbr_row.resize(out.nbr_start[n_blocks]);
  for (int B = 0; B < n_blocks; ++B) {
    int row = 0;
    for (std::size_t i = 0; i < cols[B].size(); ++i) {
      const int Bp = cols[B][i];
      out.nbr[out.nbr_start[B] + i] = Bp;
      out.nbr_row[out.nbr_start[B] + i] = row;
      row += map.block_start[Bp + 1] - map.block_start[Bp];
    }
    std::vector<int>().swap(cols[B]);
  }

  // Scalar pattern: column j of block B holds every equation of its neighbours before B, then
  // those of B up to j; blocks are numbered in equation order, so the rows come out sorted.
  Eigen::SparseMatrix<double>& K = out.K;
  K.resize(n, n);
  int* outer = K.outerIndexPtr();
  outer[0] = 0;
  for (int B = 0; B < n_blocks; ++B) {
    const int before = out.nbr_row[out.nbr_start[B + 1] - 1];
    for (int j = map.block_start[B]; j < map.block_start[B + 1]; ++j)
      outer[j + 1] = outer[j] + before + (j - map.block_start[B]) + 1;
  }
  K.resizeNonZeros(outer[n]);
  outer = K.outerIndexPtr();
  int* inner = K.innerIndexPtr();
  tbb::parallel_for(tbb::blocked_range<int>(0, n_blocks, 256), [&](const tbb::blocked_range<int>& r) {
    for (int B = r.begin(); B < r.end(); ++B)
      for (int j = map.block_start[B]; j < map.block_start[B + 1]; ++j) {
        int* row = inner + outer[j];
        for (int k = out.nbr_start[B]; k < out.nbr_start[B + 1]; ++k) {
          const int Bp = out.nbr[k];
          const int last = Bp == B ? j + 1 : map.block_start[Bp + 1];
          for (int i = map.block_start[Bp]; i < last; ++i) *row++ = i;
        }
      }
  });
  std::fill(K.valuePtr(), K.valuePtr() + K.nonZeros(), 0.0);
  out.f = Eigen::VectorXd::Zero(n);

  const Csr colours = colour_elements(mesh, map, by_block);
  out.colour_start = colours.start;
  out.colour_elements = colours.items;
  return out;
}

namespace {

// The element's blocks, equations and lifting values (prescribed values and suture offsets of
// its dofs, taken from `g`); returns whether any lifting value is nonzero.
bool gather_element(const Element& el, const DofMap& map, const double* g, int* blk, int* eq,
                    double* ge) {
  bool has_g = false;
  for (int a = 0; a < el.n_nodes(); ++a) {
    blk[a] = map.node_block[el.nodes[a]];
    for (int c = 0; c < 3; ++c) {
      const std::size_t d = 3 * static_cast<std::size_t>(el.nodes[a]) + c;
      eq[3 * a + c] = map.eq[d];
      ge[3 * a + c] = g ? g[d] : 0.0;
      has_g = has_g || ge[3 * a + c] != 0.0;
    }
  }
  return has_g;
}

// Adds the element matrix Ke into the upper triangle of sys.K.
void scatter_matrix(Assembly& sys, const DofMap& map, int nn, const int* blk, const int* eq,
                    const Eigen::MatrixXd& Ke) {
  const int* outer = sys.K.outerIndexPtr();
  double* val = sys.K.valuePtr();
  // Node pair (a, b) with block(a) <= block(b) adds its 3×3 block to column block(b).
  for (int b = 0; b < nn; ++b) {
    const int Bb = blk[b];
    if (Bb < 0) continue;
    const int* nb = sys.nbr.data() + sys.nbr_start[Bb];
    const int n_nb = sys.nbr_start[Bb + 1] - sys.nbr_start[Bb];
    for (int a = 0; a < nn; ++a) {
      const int Ba = blk[a];
      if (Ba < 0 || Ba > Bb) continue;
      const int k = static_cast<int>(std::lower_bound(nb, nb + n_nb, Ba) - nb);
      const int row0 = sys.nbr_row[sys.nbr_start[Bb] + k] - map.block_start[Ba];
      for (int cj = 0; cj < 3; ++cj) {
        const int j = eq[3 * b + cj];
        if (j < 0) continue;
        double* column = val + outer[j] + row0;
        for (int ci = 0; ci < 3; ++ci) {
          const int ri = eq[3 * a + ci];
          if (ri < 0 || (Ba == Bb && ri > j)) continue;
          column[ri] += Ke(3 * a + ci, 3 * b + cj);
        }
      }
    }
  }
}

// f_r -= T^T Ke ge (the lifting of prescribed values and suture offsets).
void scatter_lifting(double* f, int m, const int* eq, const Eigen::MatrixXd& Ke, const double* ge) {
  for (int p = 0; p < m; ++p) {
    if (eq[p] < 0) continue;
    double s = 0;
    for (int q = 0; q < m; ++q) s += Ke(p, q) * ge[q];
    f[eq[p]] -= s;
  }
}

}  // namespace

void add_loads(const Mesh& mesh, const DofMap& map, double scale, Eigen::VectorXd& f) {
  for (const NodalLoad& l : mesh.loads)
    for (int c = 0; c < 3; ++c) {
      const int e = map.eq[3 * static_cast<std::size_t>(l.node) + c];
      if (e >= 0) f[e] += scale == 1.0 ? l.force_n[c] : scale * l.force_n[c];
    }
}

namespace {

// Per-thread buffers of one element's assembly.
struct ElementScratch {
  Eigen::MatrixXd Ke;
  Eigen::VectorXd fe, ue;
  Eigen::MatrixX3d X;
  int eq[60], blk[20];
  double ge[60];
};

// Runs body(e, scratch) over every element, colour by colour, in parallel within a colour (no
// two elements of a colour share a block, so their scatters do not race); scratch.X holds the
// element's coordinates.
template <class Body>
void for_each_coloured_element(const Mesh& mesh, const Assembly& sys, Body&& body) {
  const int n_colours = static_cast<int>(sys.colour_start.size()) - 1;
  for (int colour = 0; colour < n_colours; ++colour)
    tbb::parallel_for(
        tbb::blocked_range<int>(sys.colour_start[colour], sys.colour_start[colour + 1], 8),
        [&](const tbb::blocked_range<int>& r) {
          ElementScratch w;
          for (int i = r.begin(); i < r.end(); ++i) {
            const int e = sys.colour_elements[i];
            const Element& el = mesh.elements[e];
            w.X.resize(el.n_nodes(), 3);
            for (int a = 0; a < el.n_nodes(); ++a) w.X.row(a) = mesh.nodes.row(el.nodes[a]);
            body(e, w);
          }
        });
}

}  // namespace

const IsotropicElastic& small_strain_material(const Mesh& mesh, int layer) {
  const Material& m = *mesh.materials.at(layer);
  if (const IsotropicElastic* iso = m.small_strain()) return *iso;
  throw InvalidInput(cat("layer ", layer, ": the small-strain solve has no form of the '", m.name(),
                         "' material (only of isotropic ones: linear, neo-hookean); use the "
                         "finite-strain solve"));
}

void assemble_values(const Mesh& mesh, const DofMap& map, Assembly& sys) {
  add_loads(mesh, map, 1.0, sys.f);
  double* f = sys.f.data();
  for_each_coloured_element(mesh, sys, [&](int e, ElementScratch& w) {
    const Element& el = mesh.elements[e];
    const IsotropicElastic& mat = small_strain_material(mesh, el.layer);
    stiffness_kernel(el.type, w.X, mat.lambda_mpa(), mat.mu_mpa(), e, w.Ke, mesh.wedge_rule);
    const bool has_g = gather_element(el, map, map.g.data(), w.blk, w.eq, w.ge);
    scatter_matrix(sys, map, el.n_nodes(), w.blk, w.eq, w.Ke);
    if (has_g) scatter_lifting(f, 3 * el.n_nodes(), w.eq, w.Ke, w.ge);
  });
}

FiniteAssembly assemble_finite(const Mesh& mesh, const DofMap& map,
                               const FiniteMaterials& materials, const Eigen::VectorXd& u,
                               double load_factor, const Eigen::VectorXd& lift, bool with_tangent,
                               Assembly& sys, Eigen::VectorXd* unit_lift,
                               const LayerPrestretch& prestretch) {
  if (with_tangent) std::fill(sys.K.valuePtr(), sys.K.valuePtr() + sys.K.nonZeros(), 0.0);
  sys.f.setZero(map.n_eq);
  if (unit_lift) unit_lift->setZero(map.n_eq);
  add_loads(mesh, map, load_factor, sys.f);
  double* f = sys.f.data();
  const int n_el = static_cast<int>(mesh.elements.size());
  std::vector<FiniteKernelResult> per_element(n_el);
  // The lowest id of an element found inverted so far. The assembly has then failed and only
  // that id is reported (the line search halves its step, the step is cut back): an element
  // with a higher id is skipped, one with a lower id only checked for an inversion (24 of the 85
  // assemblies of the page's default Z-plasty on Cranium's forehead meet one, line-search trials
  // and cut-back attempts; in full they cost as much as any other). The reported element, Gauss point and
  // det F are those of the full assembly, whatever the thread count.
  std::atomic<int> lowest_inverted{std::numeric_limits<int>::max()};
  for_each_coloured_element(mesh, sys, [&](int e, ElementScratch& w) {
    const int failed_at = lowest_inverted.load(std::memory_order_relaxed);
    if (e > failed_at) return;
    const Element& el = mesh.elements[e];
    const int nn = el.n_nodes(), m = 3 * nn;
    w.ue.resize(m);
    for (int a = 0; a < nn; ++a)
      w.ue.segment<3>(3 * a) = u.segment<3>(3 * static_cast<Eigen::Index>(el.nodes[a]));
    const bool failed = failed_at != std::numeric_limits<int>::max();
    per_element[e] =
        failed ? first_inversion(el.type, w.X, w.ue, e, mesh.wedge_rule)
               : finite_kernel(el.type, w.X, *materials.at(el.layer), w.ue, e, w.fe,
                               with_tangent ? &w.Ke : nullptr,
                               el.layer == prestretch.layer ? prestretch.stretch : 1.0, mesh.wedge_rule);
    if (failed || per_element[e].inverted_at >= 0) {
      int seen = lowest_inverted.load(std::memory_order_relaxed);
      while (per_element[e].inverted_at >= 0 && e < seen &&
             !lowest_inverted.compare_exchange_weak(seen, e, std::memory_order_relaxed)) {
      }
      return;
    }
    const bool has_lift = gather_element(el, map, lift.size() ? lift.data() : nullptr, w.blk, w.eq, w.ge);
    for (int p = 0; p < m; ++p)
      if (w.eq[p] >= 0) f[w.eq[p]] -= w.fe[p];
    if (!with_tangent) return;
    scatter_matrix(sys, map, nn, w.blk, w.eq, w.Ke);
    if (has_lift) scatter_lifting(f, m, w.eq, w.Ke, w.ge);
    if (unit_lift && gather_element(el, map, map.g.data(), w.blk, w.eq, w.ge))
      scatter_lifting(unit_lift->data(), m, w.eq, w.Ke, w.ge);
  });
  FiniteAssembly out;
  for (int e = 0; e < n_el; ++e) {  // the lowest element id, whatever the thread count
    if (per_element[e].inverted_at >= 0 && out.inverted_element < 0) {
      out.inverted_element = e;
      out.inverted_gauss_point = per_element[e].inverted_at;
      out.det_F = per_element[e].det_F;
    }
    out.energy_mj += per_element[e].energy_mj;
  }
  return out;
}

double add_sliding_supports(const Mesh& mesh, const DofMap& map, const Eigen::VectorXd& u,
                            const Eigen::VectorXd& lift, bool finite_strain, bool with_tangent,
                            Assembly& sys, Eigen::VectorXd* unit_lift) {
  double energy = 0;
  for (const SlidingNode& s : mesh.sliding) {
    const Eigen::Index base = 3 * static_cast<Eigen::Index>(s.node);
    const double k = s.stiffness_n_per_mm;
    // The penalty's direction n, the force -k r n at u with the lifting term -k n (n . lift),
    // and the tangent k n n^T: r = n . u along a fixed normal, r = phi(X + u) - phi(X) with n
    // = grad phi(X + u) on the curved surface (the tangent then omits k r Hess phi, which
    // vanishes as the penalty closes r; Wriggers 2006, Computational Contact Mechanics,
    // sec. 6.2, neglects the same curvature term in its penalty contact tangent).
    Eigen::Vector3d n;
    double r;
    if (s.on_surface && mesh.sliding_surface && finite_strain) {
      const Eigen::Vector3d X = mesh.nodes.row(s.node).transpose();
      n = mesh.sliding_surface->gradient(X + u.segment<3>(base));
      r = mesh.sliding_surface->distance(X + u.segment<3>(base)) - mesh.sliding_surface->distance(X);
    } else {
      n = start_normal(mesh, s);
      r = n.dot(u.segment<3>(base));
    }
    energy += 0.5 * k * r * r;
    const double rl = r + (lift.size() ? n.dot(lift.segment<3>(base)) : 0.0);
    const double gn = unit_lift ? n.dot(map.g.segment<3>(base)) : 0.0;
    for (int c = 0; c < 3; ++c) {
      const int ec = map.eq[base + c];
      if (ec < 0) continue;
      sys.f[ec] -= k * rl * n[c];
      if (unit_lift) (*unit_lift)[ec] -= k * gn * n[c];
      if (!with_tangent) continue;
      for (int d = c; d < 3; ++d) {
        const int ed = map.eq[base + d];
        if (ed < 0) continue;
        const double v = k * n[c] * n[d];
        sys.K.coeffRef(std::min(ec, ed), std::max(ec, ed)) += v;
      }
    }
  }
  return energy;
}

double add_ties(const Mesh& mesh, const DofMap& map, const Eigen::VectorXd& u,
                const Eigen::VectorXd& lift, bool with_tangent, Assembly& sys,
                Eigen::VectorXd* unit_lift) {
  double energy = 0;
  std::vector<int> node, blk, eq;
  std::vector<double> coef;
  Eigen::MatrixXd Ke;
  for (std::size_t i = 0; i < mesh.ties.size(); ++i) {
    const TiedNode& t = mesh.ties[i];
    const double k = map.tie_stiffness[i];
    // gap = sum_a c_a u_a with c = (1, -w_1, ..., -w_n) over (slave, masters).
    const int nn = static_cast<int>(t.masters.size()) + 1;
    node.assign(1, t.node);
    node.insert(node.end(), t.masters.begin(), t.masters.end());
    coef.assign(1, 1.0);
    for (double w : t.weights) coef.push_back(-w);
    const auto gap_of = [&](const Eigen::VectorXd& v) {
      Eigen::Vector3d g = Eigen::Vector3d::Zero();
      for (int a = 0; a < nn; ++a) g += coef[a] * v.segment<3>(3 * static_cast<Eigen::Index>(node[a]));
      return g;
    };
    const Eigen::Vector3d gap = gap_of(u);
    energy += 0.5 * k * gap.squaredNorm();
    const Eigen::Vector3d gl = lift.size() ? Eigen::Vector3d(gap + gap_of(lift)) : gap;
    const Eigen::Vector3d gg = unit_lift ? gap_of(map.g) : Eigen::Vector3d::Zero();
    eq.resize(3 * static_cast<std::size_t>(nn));
    blk.resize(static_cast<std::size_t>(nn));
    for (int a = 0; a < nn; ++a) {
      blk[a] = map.node_block[node[a]];
      for (int c = 0; c < 3; ++c) {
        const int e = map.eq[3 * static_cast<std::size_t>(node[a]) + c];
        eq[3 * a + c] = e;
        if (e < 0) continue;
        sys.f[e] -= k * coef[a] * gl[c];
        if (unit_lift) (*unit_lift)[e] -= k * coef[a] * gg[c];
      }
    }
    if (!with_tangent) continue;
    Ke.setZero(3 * nn, 3 * nn);  // k (c c^T) ⊗ I
    for (int a = 0; a < nn; ++a)
      for (int b = 0; b < nn; ++b)
        for (int c = 0; c < 3; ++c) Ke(3 * a + c, 3 * b + c) = k * coef[a] * coef[b];
    scatter_matrix(sys, map, nn, blk.data(), eq.data(), Ke);
  }
  return energy;
}

}  // namespace caps::fem::detail

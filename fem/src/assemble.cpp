#include "assemble.hpp"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>

#include "caps/fem/elements.hpp"
#include "elements_impl.hpp"

namespace caps::fem::detail {
namespace {

void element_equations(const Element& el, const DofMap& map, int* eq) {
  for (int a = 0; a < el.n_nodes(); ++a)
    for (int c = 0; c < 3; ++c) eq[3 * a + c] = map.eq[3 * static_cast<std::size_t>(el.nodes[a]) + c];
}

}  // namespace

Assembly assemble(const Mesh& mesh, const DofMap& map) {
  const int n = map.n_eq;
  const int n_el = static_cast<int>(mesh.elements.size());

  // Equation -> elements (CSR).
  std::vector<int> start(n + 1, 0), list;
  {
    int eq[60];
    for (const Element& el : mesh.elements) {
      element_equations(el, map, eq);
      for (int p = 0; p < 3 * el.n_nodes(); ++p)
        if (eq[p] >= 0) ++start[eq[p] + 1];
    }
    for (int i = 0; i < n; ++i) start[i + 1] += start[i];
    list.resize(start[n]);
    std::vector<int> fill(start.begin(), start.end() - 1);
    for (int e = 0; e < n_el; ++e) {
      element_equations(mesh.elements[e], map, eq);
      for (int p = 0; p < 3 * mesh.elements[e].n_nodes(); ++p)
        if (eq[p] >= 0 && (fill[eq[p]] == start[eq[p]] || list[fill[eq[p]] - 1] != e))
          list[fill[eq[p]]++] = e;
      }
    // Duplicates (an element listing one equation twice through a suture) leave gaps: mark them.
    for (int i = 0; i < n; ++i) std::fill(list.begin() + fill[i], list.begin() + start[i + 1], -1);
  }

  // Column pattern: rows r <= j coupled to j through some element.
  std::vector<std::vector<int>> cols(n);
  tbb::enumerable_thread_specific<std::vector<int>> marks([n] { return std::vector<int>(n, -1); });
  tbb::parallel_for(tbb::blocked_range<int>(0, n, 256), [&](const tbb::blocked_range<int>& r) {
    auto& mark = marks.local();
    int eq[60];
    for (int j = r.begin(); j < r.end(); ++j) {
      auto& c = cols[j];
      for (int k = start[j]; k < start[j + 1]; ++k) {
        if (list[k] < 0) continue;
        const Element& el = mesh.elements[list[k]];
        element_equations(el, map, eq);
        for (int p = 0; p < 3 * el.n_nodes(); ++p)
          if (eq[p] >= 0 && eq[p] <= j && mark[eq[p]] != j) {
            mark[eq[p]] = j;
            c.push_back(eq[p]);
          }
      }
      std::sort(c.begin(), c.end());
    }
  });
  Assembly out;
  Eigen::SparseMatrix<double>& K = out.K;
  K.resize(n, n);
  long nnz = 0;
  for (const auto& c : cols) nnz += static_cast<long>(c.size());
  K.resizeNonZeros(nnz);
  int* outer = K.outerIndexPtr();
  int* inner = K.innerIndexPtr();
  double* val = K.valuePtr();
  outer[0] = 0;
  for (int j = 0; j < n; ++j) {
    std::copy(cols[j].begin(), cols[j].end(), inner + outer[j]);
    outer[j + 1] = outer[j] + static_cast<int>(cols[j].size());
    std::vector<int>().swap(cols[j]);
  }
  std::fill(val, val + nnz, 0.0);

  out.f = Eigen::VectorXd::Zero(n);
  for (const NodalLoad& l : mesh.loads)
    for (int c = 0; c < 3; ++c) {
      const int e = map.eq[3 * static_cast<std::size_t>(l.node) + c];
      if (e >= 0) out.f[e] += l.force_n[c];
    }
  double* f = out.f.data();
  tbb::parallel_for(tbb::blocked_range<int>(0, n_el, 16), [&](const tbb::blocked_range<int>& r) {
    Eigen::MatrixXd Ke;
    Eigen::MatrixX3d X;
    int eq[60];
    double ge[60];
    for (int e = r.begin(); e < r.end(); ++e) {
      const Element& el = mesh.elements[e];
      const int nn = el.n_nodes(), m = 3 * nn;
      X.resize(nn, 3);
      for (int a = 0; a < nn; ++a) X.row(a) = mesh.nodes.row(el.nodes[a]);
      const LinearElastic& mat = mesh.materials.at(el.layer);
      stiffness_kernel(el.type, X, mat.lambda_mpa(), mat.mu_mpa(), e, Ke);
      element_equations(el, map, eq);
      bool has_g = false;
      for (int a = 0; a < nn; ++a)
        for (int c = 0; c < 3; ++c) {
          ge[3 * a + c] = map.g[3 * static_cast<std::size_t>(el.nodes[a]) + c];
          has_g = has_g || ge[3 * a + c] != 0.0;
        }
      for (int q = 0; q < m; ++q) {
        const int s = eq[q];
        if (s < 0) continue;
        const int* rows = inner + outer[s];
        const int len = outer[s + 1] - outer[s];
        for (int p = 0; p < m; ++p) {
          const int rr = eq[p];
          if (rr < 0 || rr > s) continue;
          const int k = static_cast<int>(std::lower_bound(rows, rows + len, rr) - rows);
          std::atomic_ref<double>(val[outer[s] + k]).fetch_add(Ke(p, q), std::memory_order_relaxed);
        }
      }
      if (has_g)  // lifting: f_r -= T^T K g (prescribed values and suture offsets)
        for (int p = 0; p < m; ++p) {
          if (eq[p] < 0) continue;
          double s = 0;
          for (int q = 0; q < m; ++q) s += Ke(p, q) * ge[q];
          if (s != 0.0) std::atomic_ref<double>(f[eq[p]]).fetch_add(-s, std::memory_order_relaxed);
        }
    }
  });
  return out;
}

}  // namespace caps::fem::detail

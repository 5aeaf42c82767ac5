#include "caps/volume/isosurface.hpp"

#include "caps/core/error.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <Eigen/Geometry>
#include <Eigen/LU>

#include <algorithm>
#include <array>
#include <bit>
#include <climits>
#include <cmath>
#include <cstdint>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace caps {
namespace {

// ---------------------------------------------------------------------------------------------
// Case table. Corner c of a cube sits at (c & 1, (c >> 1) & 1, (c >> 2) & 1); bit c of the case
// index is set when the value there is > iso ("inside"). Edges 0-3 run along x, 4-7 along y,
// 8-11 along z. Rather than transcribing the classic 256-case table (whose complementary cases
// crack against their neighbours), the table is derived once from a rule that depends only on a
// face's own four signs, so both cubes sharing a face draw the same contour segments on it:
//   * a face with its two inside corners on a diagonal gets two segments, one around each inside
//     corner (inside is 6-connected across faces, outside 18-connected);
//   * the segments of the six faces chain into closed loops, each loop is one polygon;
//   * each polygon is triangulated (min-weight DP) without diagonals joining two vertices that
//     lie on the same cube face, because the neighbouring cube could draw the same diagonal and
//     the edge would then have four triangles. The generator asserts this is always possible.

constexpr int kEdgeCorners[12][2] = {{0, 1}, {2, 3}, {4, 5}, {6, 7}, {0, 2}, {1, 3},
                                     {4, 6}, {5, 7}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};

struct CaseTable {
  std::array<std::uint8_t, 256> n_tri{};
  std::array<std::array<std::int8_t, 30>, 256> tri{};  // at most 10 triangles per case
  std::array<std::uint16_t, 256> edge_mask{};          // bit e: edge e is crossed
};

Eigen::Vector3d corner_pos(int c) { return {double(c & 1), double((c >> 1) & 1), double(c >> 2)}; }

int edge_of(int a, int b) {
  for (int e = 0; e < 12; ++e)
    if ((kEdgeCorners[e][0] == a && kEdgeCorners[e][1] == b) ||
        (kEdgeCorners[e][0] == b && kEdgeCorners[e][1] == a))
      return e;
  return -1;
}

Eigen::Vector3d edge_mid(int e) {
  return 0.5 * (corner_pos(kEdgeCorners[e][0]) + corner_pos(kEdgeCorners[e][1]));
}

// Two cube edges lie on a common face iff their midpoints share a coordinate equal to 0 or 1
// along an axis that neither edge runs along.
bool share_face(int a, int b) {
  const Eigen::Vector3d ma = edge_mid(a), mb = edge_mid(b);
  for (int ax = 0; ax < 3; ++ax)
    if (ma[ax] != 0.5 && ma[ax] == mb[ax]) return true;
  return false;
}

CaseTable build_case_table() {
  CaseTable t;
  for (int cs = 0; cs < 256; ++cs) {
    auto inside = [&](int c) { return ((cs >> c) & 1) != 0; };
    std::array<int, 12> next;  // oriented segment: edge -> following edge, -1 if none
    next.fill(-1);
    int n_in_edges = 0;
    for (int e = 0; e < 12; ++e)
      if (inside(kEdgeCorners[e][0]) != inside(kEdgeCorners[e][1])) {
        t.edge_mask[cs] |= std::uint16_t(1u << e);
        ++n_in_edges;
      }
    for (int axis = 0; axis < 3; ++axis)
      for (int side = 0; side < 2; ++side) {
        const int b = (axis + 1) % 3, c = (axis + 2) % 3;
        int fc[4];
        const int uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
        for (int q = 0; q < 4; ++q) fc[q] = (side << axis) | (uv[q][0] << b) | (uv[q][1] << c);
        Eigen::Vector3d n_out = Eigen::Vector3d::Zero();
        n_out[axis] = side ? 1.0 : -1.0;
        // Segments cut off single corners (or split the face in two halves); each is given as
        // (edge, edge, the corner it cuts off or any corner on one side).
        std::vector<std::array<int, 3>> segs;
        int n_inside = 0;
        for (int q = 0; q < 4; ++q) n_inside += inside(fc[q]);
        if (n_inside == 0 || n_inside == 4) continue;
        for (int q = 0; q < 4; ++q) {
          const int prev = fc[(q + 3) % 4], cur = fc[q], nxt = fc[(q + 1) % 4];
          const bool lone = inside(cur) != inside(prev) && inside(cur) != inside(nxt);
          // A corner differing from both neighbours is cut off, unless it is an outside corner
          // of an ambiguous face (then the inside corners are the ones cut off).
          if (lone && !(n_inside == 2 && !inside(cur)))
            segs.push_back({edge_of(prev, cur), edge_of(cur, nxt), cur});
        }
        if (segs.empty()) {  // two adjacent inside corners: one straight segment
          std::array<int, 2> es{};
          int m = 0;
          for (int q = 0; q < 4; ++q)
            if (inside(fc[q]) != inside(fc[(q + 1) % 4])) es[m++] = edge_of(fc[q], fc[(q + 1) % 4]);
          segs.push_back({es[0], es[1], fc[0]});
        }
        for (auto [ea, eb, corner] : segs) {
          const Eigen::Vector3d pa = edge_mid(ea), pb = edge_mid(eb);
          const Eigen::Vector3d dir = pb - pa;
          const Eigen::Vector3d to_c = corner_pos(corner) - 0.5 * (pa + pb);
          // Inside must be on the right of the segment seen from outside the cube, so that the
          // loop runs counter-clockwise around the outward normal (values > iso -> < iso).
          const double s = dir.cross(to_c).dot(n_out);
          const bool right = s < 0;
          if (right != inside(corner)) std::swap(ea, eb);
          if (next[ea] != -1) throw Error("isosurface case table: edge with two successors");
          next[ea] = eb;
        }
      }
    std::array<bool, 12> used{};
    int n_tri = 0;
    for (int e0 = 0; e0 < 12; ++e0) {
      if (next[e0] == -1 || used[e0]) continue;
      std::vector<int> poly;
      for (int e = e0; !used[e]; e = next[e]) {
        used[e] = true;
        poly.push_back(e);
        if (next[e] == -1) throw Error("isosurface case table: open contour");
      }
      const int k = static_cast<int>(poly.size());
      // Minimum-weight triangulation; W[a][b] is the cost of polygon chain a..b closed by a-b.
      std::vector<std::vector<double>> W(k, std::vector<double>(k, 0.0));
      std::vector<std::vector<int>> split(k, std::vector<int>(k, -1));
      auto diag_cost = [&](int a, int b) {
        if (b == a + 1 || (a == 0 && b == k - 1)) return 0.0;
        return (share_face(poly[a], poly[b]) ? 1000.0 : 0.0) +
               (edge_mid(poly[a]) - edge_mid(poly[b])).norm();
      };
      for (int len = 2; len < k; ++len)
        for (int a = 0; a + len < k; ++a) {
          const int b = a + len;
          W[a][b] = 1e300;
          for (int m = a + 1; m < b; ++m) {
            const double w = W[a][m] + W[m][b] + diag_cost(a, m) + diag_cost(m, b);
            if (w < W[a][b]) W[a][b] = w, split[a][b] = m;
          }
        }
      if (k > 3 && W[0][k - 1] >= 1000.0)
        throw Error("isosurface case table: unavoidable face diagonal");
      std::vector<std::array<int, 2>> stack{{0, k - 1}};
      while (!stack.empty()) {
        auto [a, b] = stack.back();
        stack.pop_back();
        if (b - a < 2) continue;
        const int m = split[a][b];
        t.tri[cs][3 * n_tri + 0] = std::int8_t(poly[a]);
        t.tri[cs][3 * n_tri + 1] = std::int8_t(poly[m]);
        t.tri[cs][3 * n_tri + 2] = std::int8_t(poly[b]);
        ++n_tri;
        stack.push_back({a, m});
        stack.push_back({m, b});
      }
    }
    if (n_tri > 10 || n_in_edges != static_cast<int>(std::count(used.begin(), used.end(), true)))
      throw Error("isosurface case table: inconsistent case");
    t.n_tri[cs] = std::uint8_t(n_tri);
  }
  return t;
}

const CaseTable& case_table() {
  static const CaseTable table = build_case_table();
  return table;
}

// ---------------------------------------------------------------------------------------------
// Sign bitmap: one bit per voxel (value > iso), 64 voxels of a row per word.

std::uint64_t sign_word(const float* a, int n, float iso) {
  std::uint64_t w = 0;
#if defined(__SSE2__)
  if (n == 64) {
    const __m128 t = _mm_set1_ps(iso);
    for (int b = 0; b < 64; b += 8) {
      const int m0 = _mm_movemask_ps(_mm_cmpgt_ps(_mm_loadu_ps(a + b), t));
      const int m1 = _mm_movemask_ps(_mm_cmpgt_ps(_mm_loadu_ps(a + b + 4), t));
      w |= std::uint64_t(m0 | (m1 << 4)) << b;
    }
    return w;
  }
#endif
  for (int b = 0; b < n; ++b) w |= std::uint64_t(a[b] > iso) << b;
  return w;
}

struct Grid {
  int nx, ny, nz, wpr;  // wpr: 64-bit words per row
  std::vector<std::uint64_t> bits;
  const std::uint64_t* row(int j, int k) const {
    return bits.data() + (std::size_t(k) * ny + j) * wpr;
  }
  // Bits i of word w for which a cube (i, i+1) exists.
  std::uint64_t cube_mask(int w) const {
    const int lo = 64 * w, hi = std::min(64 * w + 64, nx - 1);
    if (hi <= lo) return 0;
    return hi - lo == 64 ? ~std::uint64_t(0) : ((std::uint64_t(1) << (hi - lo)) - 1);
  }
};

// Bit i set: value i+1 of the row.
inline std::uint64_t shifted(const std::uint64_t* r, int w, int wpr) {
  return (r[w] >> 1) | (w + 1 < wpr ? r[w + 1] << 63 : 0);
}

// Per-row counts of pass 2 and offsets after the prefix sum.
struct RowCounts {
  std::int64_t nx = 0, ny = 0, nz = 0, ntri = 0;
};

// The four rows (j + dy, k + dz), slot dy + 2 dz, of a row of cubes, one word at a time.
struct CubeWords {
  std::uint64_t lo[4], hi[4];
  std::uint64_t nontrivial;
  int case_at(int b) const {
    int cs = 0;
    for (int s = 0; s < 4; ++s)
      cs |= int((lo[s] >> b) & 1) << (2 * s) | int((hi[s] >> b) & 1) << (2 * s + 1);
    return cs;
  }
};

inline CubeWords cube_words(const Grid& g, const std::uint64_t* const rows[4], int w) {
  CubeWords c;
  std::uint64_t all = ~std::uint64_t(0), any = 0;
  for (int s = 0; s < 4; ++s) {
    c.lo[s] = rows[s][w];
    c.hi[s] = shifted(rows[s], w, g.wpr);
    all &= c.lo[s] & c.hi[s];
    any |= c.lo[s] | c.hi[s];
  }
  c.nontrivial = (any & ~all) & g.cube_mask(w);
  return c;
}

}  // namespace

TriMesh extract_isosurface(const Volume& field, float iso) {
  const auto& geom = field.geom;
  if (!std::isfinite(iso))
    throw InvalidInput(cat(field.source, ": isosurface level ", iso, " is not finite"));
  if (geom.dims.minCoeff() < 0 || field.data.size() != geom.n_voxels())
    throw InvalidInput(cat(field.source, ": volume has ", field.data.size(),
                           " values but dimensions (", geom.dims.transpose(),
                           "); the volume is damaged, reload it"));
  const double det = geom.direction.determinant();
  if (!geom.direction.allFinite() || std::abs(det) < 1e-6 || !(geom.spacing_mm.minCoeff() > 0))
    throw InvalidInput(cat(field.source, ": direction (det ", det, ") or spacing (",
                           geom.spacing_mm.transpose(),
                           ") mm is unusable; run validate_volume() when loading"));
  TriMesh mesh;
  if (geom.dims.minCoeff() < 2) return mesh;

  const CaseTable& table = case_table();
  Grid g;
  g.nx = geom.dims[0];
  g.ny = geom.dims[1];
  g.nz = geom.dims[2];
  g.wpr = (g.nx + 63) / 64;
  const int nx = g.nx, ny = g.ny, nz = g.nz, wpr = g.wpr;
  g.bits.resize(std::size_t(ny) * nz * wpr);

  // Pass 1: classify every voxel once (the only pass that reads the whole volume).
  tbb::parallel_for(tbb::blocked_range<int>(0, nz), [&](const tbb::blocked_range<int>& r) {
    for (int k = r.begin(); k < r.end(); ++k)
      for (int j = 0; j < ny; ++j) {
        const float* a = field.data.data() + geom.linear(0, j, k);
        std::uint64_t* out = g.bits.data() + (std::size_t(k) * ny + j) * wpr;
        for (int w = 0; w < wpr; ++w)
          out[w] = sign_word(a + 64 * w, std::min(64, nx - 64 * w), iso);
      }
  });

  // Pass 2: per row of voxels (j, k), count crossed x, y and z edges it owns and the triangles
  // of the row of cubes whose lowest corner row it is.
  const std::size_t n_rows = std::size_t(ny) * nz;
  std::vector<RowCounts> counts(n_rows + 1);
  tbb::parallel_for(tbb::blocked_range<int>(0, nz, 1), [&](const tbb::blocked_range<int>& r) {
    for (int k = r.begin(); k < r.end(); ++k)
      for (int j = 0; j < ny; ++j) {
        RowCounts& rc = counts[std::size_t(k) * ny + j];
        const std::uint64_t* r0 = g.row(j, k);
        const std::uint64_t* ry = j + 1 < ny ? g.row(j + 1, k) : nullptr;
        const std::uint64_t* rz = k + 1 < nz ? g.row(j, k + 1) : nullptr;
        for (int w = 0; w < wpr; ++w) {
          rc.nx += std::popcount((r0[w] ^ shifted(r0, w, wpr)) & g.cube_mask(w));
          if (ry) rc.ny += std::popcount(r0[w] ^ ry[w]);
          if (rz) rc.nz += std::popcount(r0[w] ^ rz[w]);
        }
        if (!ry || !rz) continue;
        const std::uint64_t* rows[4] = {r0, ry, rz, g.row(j + 1, k + 1)};
        for (int w = 0; w < wpr; ++w) {
          const CubeWords c = cube_words(g, rows, w);
          for (std::uint64_t m = c.nontrivial; m; m &= m - 1)
            rc.ntri += table.n_tri[c.case_at(std::countr_zero(m))];
        }
      }
  });

  // Serial prefix sums turn the counts into offsets (in place): the vertices of row r are its x-,
  // then y-, then z-edge crossings, rows in memory order. Fixed offsets make the output
  // independent of how the rows are scheduled.
  std::int64_t n_vert = 0, n_tri = 0;
  for (std::size_t r = 0; r <= n_rows; ++r) {
    RowCounts c = counts[r];
    counts[r] = {n_vert, n_vert + c.nx, n_vert + c.nx + c.ny, n_tri};
    n_vert += c.nx + c.ny + c.nz;
    n_tri += c.ntri;
  }
  if (n_vert > INT_MAX || n_tri > INT_MAX)
    throw InvalidInput(cat(field.source, ": the isosurface at ", iso, " would have ", n_vert,
                           " vertices and ", n_tri,
                           " triangles, more than a mesh can index; resample the volume"));
  mesh.V.resize(n_vert, 3);
  mesh.F.resize(n_tri, 3);
  if (n_tri == 0 && n_vert == 0) return mesh;

  const Eigen::Matrix3d M = geom.direction * geom.spacing_mm.asDiagonal();
  const Eigen::Vector3d origin = geom.origin_lps;
  // Marching cubes orients in index space; a left-handed index->LPS map mirrors the mesh.
  const bool flip = det < 0;
  const float* data = field.data.data();

  // Pass 3: fill vertices and triangles at the precomputed offsets.
  tbb::parallel_for(tbb::blocked_range<int>(0, nz, 1), [&](const tbb::blocked_range<int>& r) {
    auto put_vertex = [&](std::int64_t id, double x, double y, double z) {
      const Eigen::Vector3d p = origin + M * Eigen::Vector3d(x, y, z);
      mesh.V(id, 0) = p[0];
      mesh.V(id, 1) = p[1];
      mesh.V(id, 2) = p[2];
    };
    auto frac = [&](float a, float b) {
      const double t = (double(iso) - a) / (double(b) - a);
      return t >= 0.0 && t <= 1.0 ? t : 0.5;  // only reachable with non-finite values
    };
    for (int k = r.begin(); k < r.end(); ++k)
      for (int j = 0; j < ny; ++j) {
        const std::size_t ri = std::size_t(k) * ny + j;
        const RowCounts& off = counts[ri];
        const std::uint64_t* r0 = g.row(j, k);
        const std::uint64_t* ry = j + 1 < ny ? g.row(j + 1, k) : nullptr;
        const std::uint64_t* rz = k + 1 < nz ? g.row(j, k + 1) : nullptr;
        const float* a = data + geom.linear(0, j, k);
        const float* ay = ry ? data + geom.linear(0, j + 1, k) : nullptr;
        const float* az = rz ? data + geom.linear(0, j, k + 1) : nullptr;
        std::int64_t idx = off.nx, idy = off.ny, idz = off.nz;
        for (int w = 0; w < wpr; ++w) {
          for (std::uint64_t m = (r0[w] ^ shifted(r0, w, wpr)) & g.cube_mask(w); m; m &= m - 1) {
            const int i = 64 * w + std::countr_zero(m);
            put_vertex(idx++, i + frac(a[i], a[i + 1]), j, k);
          }
          if (ry)
            for (std::uint64_t m = r0[w] ^ ry[w]; m; m &= m - 1) {
              const int i = 64 * w + std::countr_zero(m);
              put_vertex(idy++, i, j + frac(a[i], ay[i]), k);
            }
          if (rz)
            for (std::uint64_t m = r0[w] ^ rz[w]; m; m &= m - 1) {
              const int i = 64 * w + std::countr_zero(m);
              put_vertex(idz++, i, j, k + frac(a[i], az[i]));
            }
        }
        if (!ry || !rz) continue;

        // Triangles of the row of cubes. Crossings are numbered along each row in increasing i,
        // and every crossed edge left of a cube belongs to an earlier non-trivial cube of this
        // row, so running counters give each edge's vertex id without searching.
        const std::uint64_t* rows[4] = {r0, ry, rz, g.row(j + 1, k + 1)};
        const std::int64_t xbase[4] = {off.nx, counts[ri + 1].nx, counts[ri + ny].nx,
                                       counts[ri + ny + 1].nx};
        const std::int64_t ybase[2] = {off.ny, counts[ri + ny].ny};
        const std::int64_t zbase[2] = {off.nz, counts[ri + 1].nz};
        std::int64_t cx[4] = {0, 0, 0, 0}, cy[2] = {0, 0}, cz[2] = {0, 0};
        std::int64_t tid = off.ntri;
        for (int w = 0; w < wpr; ++w) {
          const CubeWords c = cube_words(g, rows, w);
          for (std::uint64_t m = c.nontrivial; m; m &= m - 1) {
            const int cs = c.case_at(std::countr_zero(m));
            const unsigned em = table.edge_mask[cs];
            auto bit = [em](int e) { return std::int64_t((em >> e) & 1); };
            std::int64_t id[12];
            for (int q = 0; q < 4; ++q) id[q] = xbase[q] + cx[q];
            id[4] = ybase[0] + cy[0];
            id[5] = id[4] + bit(4);
            id[6] = ybase[1] + cy[1];
            id[7] = id[6] + bit(6);
            id[8] = zbase[0] + cz[0];
            id[9] = id[8] + bit(8);
            id[10] = zbase[1] + cz[1];
            id[11] = id[10] + bit(10);
            const std::int8_t* t = table.tri[cs].data();
            for (int n = table.n_tri[cs]; n > 0; --n, t += 3, ++tid) {
              mesh.F(tid, 0) = int(id[t[0]]);
              mesh.F(tid, 1) = int(id[t[flip ? 2 : 1]]);
              mesh.F(tid, 2) = int(id[t[flip ? 1 : 2]]);
            }
            for (int q = 0; q < 4; ++q) cx[q] += bit(q);
            cy[0] += bit(4);
            cy[1] += bit(6);
            cz[0] += bit(8);
            cz[1] += bit(10);
          }
        }
      }
  });
  return mesh;
}

// ---------------------------------------------------------------------------------------------
// Smoothing and statistics.

namespace {

void check_faces(const TriMesh& mesh, const char* what) {
  const Eigen::Index nv = mesh.n_vertices();
  if (mesh.F.size() > 0 && (mesh.F.minCoeff() < 0 || mesh.F.maxCoeff() >= nv))
    throw InvalidInput(cat(what, ": face indices span [", mesh.F.minCoeff(), ", ",
                           mesh.F.maxCoeff(), "] but the mesh has ", nv, " vertices"));
}

// Unique neighbours of every vertex (compressed rows), each list sorted.
void vertex_neighbours(const TriMesh& mesh, std::vector<int>& start, std::vector<int>& nbr) {
  const Eigen::Index nv = mesh.n_vertices(), nf = mesh.n_faces();
  start.assign(nv + 1, 0);
  for (Eigen::Index f = 0; f < nf; ++f)
    for (int c = 0; c < 3; ++c) start[mesh.F(f, c) + 1] += 2;
  for (Eigen::Index v = 0; v < nv; ++v) start[v + 1] += start[v];
  std::vector<int> fill(start.begin(), start.end() - 1);
  nbr.resize(start[nv]);
  for (Eigen::Index f = 0; f < nf; ++f)
    for (int c = 0; c < 3; ++c) {
      const int v = mesh.F(f, c);
      nbr[fill[v]++] = mesh.F(f, (c + 1) % 3);
      nbr[fill[v]++] = mesh.F(f, (c + 2) % 3);
    }
  // Compact each list to its unique entries, then squeeze the rows together.
  std::vector<int> n_unique(nv);
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, nv), [&](const auto& r) {
    for (Eigen::Index v = r.begin(); v < r.end(); ++v) {
      auto b = nbr.begin() + start[v], e = nbr.begin() + start[v + 1];
      std::sort(b, e);
      n_unique[v] = int(std::unique(b, e) - b);
    }
  });
  int out = 0;
  for (Eigen::Index v = 0; v < nv; ++v) {
    const int b = start[v];
    start[v] = out;
    for (int q = 0; q < n_unique[v]; ++q) nbr[out++] = nbr[b + q];
  }
  start[nv] = out;
  nbr.resize(out);
}

}  // namespace

void smooth_taubin(TriMesh& mesh, int iterations, double lambda, double mu) {
  if (iterations < 0)
    throw InvalidInput(cat("smooth_taubin: iterations = ", iterations, " must be >= 0"));
  if (!(lambda > 0 && lambda < 1) || !(mu < -lambda))
    throw InvalidInput(cat("smooth_taubin: lambda = ", lambda, ", mu = ", mu,
                           " must satisfy 0 < lambda < 1 and mu < -lambda (e.g. 0.5, -0.53)"));
  check_faces(mesh, "smooth_taubin");
  if (iterations == 0 || mesh.n_faces() == 0) return;
  std::vector<int> start, nbr;
  vertex_neighbours(mesh, start, nbr);
  const Eigen::Index nv = mesh.n_vertices();
  // Row-major copies: each umbrella step gathers whole neighbour positions.
  std::vector<Eigen::Vector3d> P(nv), Q(nv);
  for (Eigen::Index v = 0; v < nv; ++v) P[v] = mesh.V.row(v).transpose();
  auto step = [&](const std::vector<Eigen::Vector3d>& src, std::vector<Eigen::Vector3d>& dst,
                  double factor) {
    tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, nv, 4096), [&](const auto& r) {
      for (Eigen::Index v = r.begin(); v < r.end(); ++v) {
        const int b = start[v], e = start[v + 1];
        if (b == e) {
          dst[v] = src[v];
          continue;
        }
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        for (int q = b; q < e; ++q) sum += src[nbr[q]];
        // x <- x + factor * (mean of neighbours - x)  (Taubin 1995, eq. 4, umbrella weights)
        dst[v] = src[v] + factor * (sum / double(e - b) - src[v]);
      }
    });
  };
  for (int it = 0; it < iterations; ++it) {
    step(P, Q, lambda);
    step(Q, P, mu);
  }
  for (Eigen::Index v = 0; v < nv; ++v) mesh.V.row(v) = P[v].transpose();
}

double mesh_area(const TriMesh& mesh) {
  check_faces(mesh, "mesh_area");
  return tbb::parallel_reduce(
      tbb::blocked_range<Eigen::Index>(0, mesh.n_faces(), 8192), 0.0,
      [&](const auto& r, double acc) {
        for (Eigen::Index f = r.begin(); f < r.end(); ++f) {
          const Eigen::Vector3d a = mesh.V.row(mesh.F(f, 0)), b = mesh.V.row(mesh.F(f, 1)),
                                c = mesh.V.row(mesh.F(f, 2));
          acc += 0.5 * (b - a).cross(c - a).norm();
        }
        return acc;
      },
      std::plus<double>());
}

double mesh_volume(const TriMesh& mesh) {
  check_faces(mesh, "mesh_volume");
  if (mesh.n_faces() == 0) return 0.0;
  // Relative to the centroid of the vertices: the sum is translation invariant for a closed mesh
  // and this keeps the products small (less cancellation far from the origin).
  const Eigen::RowVector3d c = mesh.V.colwise().mean();
  return tbb::parallel_reduce(
      tbb::blocked_range<Eigen::Index>(0, mesh.n_faces(), 8192), 0.0,
      [&](const auto& r, double acc) {
        for (Eigen::Index f = r.begin(); f < r.end(); ++f) {
          const Eigen::Vector3d a = mesh.V.row(mesh.F(f, 0)) - c, b = mesh.V.row(mesh.F(f, 1)) - c,
                                d = mesh.V.row(mesh.F(f, 2)) - c;
          acc += a.dot(b.cross(d)) / 6.0;
        }
        return acc;
      },
      std::plus<double>());
}

bool is_closed_manifold(const TriMesh& mesh) {
  const Eigen::Index nf = mesh.n_faces(), nv = mesh.n_vertices();
  if (nf == 0) return false;
  std::vector<std::uint64_t> half(3 * nf);
  for (Eigen::Index f = 0; f < nf; ++f)
    for (int c = 0; c < 3; ++c) {
      const std::int64_t a = mesh.F(f, c), b = mesh.F(f, (c + 1) % 3);
      if (a < 0 || b < 0 || a >= nv || b >= nv || a == b) return false;
      half[3 * f + c] = (std::uint64_t(a) << 32) | std::uint64_t(b);
    }
  std::sort(half.begin(), half.end());
  for (std::size_t h = 0; h < half.size(); ++h) {
    if (h + 1 < half.size() && half[h] == half[h + 1]) return false;  // same direction twice
    const std::uint64_t rev = (half[h] << 32) | (half[h] >> 32);
    if (!std::binary_search(half.begin(), half.end(), rev)) return false;
  }
  return true;
}

}  // namespace caps

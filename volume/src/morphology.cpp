#include "caps/volume/morphology.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <numeric>

namespace caps {
namespace {

// One line of the lower-envelope algorithm (Felzenszwalb & Huttenlocher 2012, Algorithm 1),
// with spacing h: d(q) = min_p f(p) + h^2 (q - p)^2. Also carries the argmin's feature index.
struct LineBuffers {
  std::vector<float> f, d;
  std::vector<std::int64_t> feat_in, feat_out;
  std::vector<int> v;
  std::vector<double> z;
  void resize(int n) {
    f.resize(n); d.resize(n); feat_in.resize(n); feat_out.resize(n);
    v.resize(n); z.resize(n + 1);
  }
};

void envelope_1d(LineBuffers& b, int n, double h, bool with_features) {
  const double h2 = h * h;
  auto intersect = [&](int q, int p) {
    return ((b.f[q] + h2 * double(q) * q) - (b.f[p] + h2 * double(p) * p)) / (2.0 * h2 * (q - p));
  };
  int k = -1;
  for (int q = 0; q < n; ++q) {
    if (b.f[q] >= kFar) continue;  // not a site: no parabola
    if (k < 0) {
      k = 0; b.v[0] = q; b.z[0] = -1e300; b.z[1] = 1e300;
      continue;
    }
    double s = intersect(q, b.v[k]);
    while (s <= b.z[k]) s = intersect(q, b.v[--k]);  // z[0] = -inf ends the loop
    ++k;
    b.v[k] = q; b.z[k] = s; b.z[k + 1] = 1e300;
  }
  if (k < 0) {
    for (int q = 0; q < n; ++q) { b.d[q] = kFar; if (with_features) b.feat_out[q] = -1; }
    return;
  }
  int j = 0;
  for (int q = 0; q < n; ++q) {
    while (b.z[j + 1] < q) ++j;
    const int p = b.v[j];
    b.d[q] = static_cast<float>(h2 * double(q - p) * (q - p) + b.f[p]);
    if (with_features) b.feat_out[q] = b.feat_in[p];
  }
}

// Runs the 1-D transform along `axis` for every line of the grid, in place. Lines along j and k
// are strided in memory, so they are processed kBlock neighbouring i-lines at a time: each row of
// the block is one contiguous read, which keeps the passes cache-friendly.
void transform_axis(const VolumeGeometry& g, int axis, std::vector<float>& dist,
                    std::vector<std::int64_t>* feat) {
  constexpr int kBlock = 16;
  const int n = g.dims[axis];
  const std::int64_t stride[3] = {1, g.dims[0], std::int64_t(g.dims[0]) * g.dims[1]};
  const double h = g.spacing_mm[axis];
  if (axis == 0) {
    tbb::parallel_for(tbb::blocked_range<int>(0, g.dims[2]), [&](const tbb::blocked_range<int>& r) {
      LineBuffers b;
      b.resize(n);
      for (int k = r.begin(); k < r.end(); ++k)
        for (int j = 0; j < g.dims[1]; ++j) {
          const std::int64_t base = j * stride[1] + k * stride[2];
          std::copy_n(dist.begin() + base, n, b.f.begin());
          if (feat) std::copy_n(feat->begin() + base, n, b.feat_in.begin());
          envelope_1d(b, n, h, feat != nullptr);
          std::copy_n(b.d.begin(), n, dist.begin() + base);
          if (feat) std::copy_n(b.feat_out.begin(), n, feat->begin() + base);
        }
    });
    return;
  }
  const int other = axis == 1 ? 2 : 1;
  const int n_blocks = (g.dims[0] + kBlock - 1) / kBlock;
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, std::int64_t(g.dims[other]) * n_blocks),
                    [&](const tbb::blocked_range<std::int64_t>& r) {
    LineBuffers b;
    b.resize(n);
    std::vector<float> f(std::size_t(kBlock) * n);
    std::vector<std::int64_t> fe(feat ? std::size_t(kBlock) * n : 0);
    for (std::int64_t t = r.begin(); t < r.end(); ++t) {
      const int o = static_cast<int>(t / n_blocks);
      const int i0 = static_cast<int>(t % n_blocks) * kBlock;
      const int nb = std::min(kBlock, g.dims[0] - i0);
      const std::int64_t base = o * stride[other] + i0;
      for (int q = 0; q < n; ++q)
        for (int c = 0; c < nb; ++c) {
          f[std::size_t(c) * n + q] = dist[base + q * stride[axis] + c];
          if (feat) fe[std::size_t(c) * n + q] = (*feat)[base + q * stride[axis] + c];
        }
      for (int c = 0; c < nb; ++c) {
        std::copy_n(f.begin() + std::size_t(c) * n, n, b.f.begin());
        if (feat) std::copy_n(fe.begin() + std::size_t(c) * n, n, b.feat_in.begin());
        envelope_1d(b, n, h, feat != nullptr);
        std::copy_n(b.d.begin(), n, f.begin() + std::size_t(c) * n);
        if (feat) std::copy_n(b.feat_out.begin(), n, fe.begin() + std::size_t(c) * n);
      }
      for (int q = 0; q < n; ++q)
        for (int c = 0; c < nb; ++c) {
          dist[base + q * stride[axis] + c] = f[std::size_t(c) * n + q];
          if (feat) (*feat)[base + q * stride[axis] + c] = fe[std::size_t(c) * n + q];
        }
    }
  });
}

Mask same_grid(const Mask& m) {
  Mask out;
  out.geom = m.geom;
  out.data.assign(m.data.size(), 0);
  return out;
}

}  // namespace

std::vector<float> squared_distance_mm2(const Mask& sites, std::vector<std::int64_t>* nearest) {
  const std::size_t n = sites.data.size();
  std::vector<float> dist(n);
  for (std::size_t i = 0; i < n; ++i) dist[i] = sites.data[i] ? 0.0f : kFar;
  if (nearest) {
    nearest->resize(n);
    for (std::size_t i = 0; i < n; ++i) (*nearest)[i] = sites.data[i] ? std::int64_t(i) : -1;
  }
  for (int axis = 0; axis < 3; ++axis) transform_axis(sites.geom, axis, dist, nearest);
  return dist;
}

namespace {

// The voxel offsets within radius_mm of the centre (a digital ball), or empty if the ball spans
// more than kMaxReach voxels along an axis, where a distance transform is cheaper.
std::vector<Eigen::Vector3i> ball_offsets(const VolumeGeometry& g, double radius_mm) {
  constexpr int kMaxReach = 2;
  Eigen::Vector3i reach;
  for (int a = 0; a < 3; ++a) reach[a] = static_cast<int>(std::floor(radius_mm / g.spacing_mm[a]));
  if (reach.maxCoeff() > kMaxReach) return {};
  std::vector<Eigen::Vector3i> offsets;
  for (int k = -reach[2]; k <= reach[2]; ++k)
    for (int j = -reach[1]; j <= reach[1]; ++j)
      for (int i = -reach[0]; i <= reach[0]; ++i)
        if (g.spacing_mm.cwiseProduct(Eigen::Vector3d(i, j, k)).norm() <= radius_mm &&
            (i || j || k))
          offsets.emplace_back(i, j, k);
  return offsets;
}

// Dilation of `m` by a small digital ball: out = 1 where any offset neighbour is `value`
// (value 1: dilation of m; value 0: dilation of the background, i.e. the complement of erosion).
Mask stencil(const Mask& m, const std::vector<Eigen::Vector3i>& offsets, std::uint8_t value) {
  Mask out;
  out.geom = m.geom;
  out.data.assign(m.data.size(), 0);
  const auto& d = m.geom.dims;
  Eigen::Vector3i reach = Eigen::Vector3i::Zero();
  std::vector<std::ptrdiff_t> linear;
  for (const auto& o : offsets) {
    reach = reach.cwiseMax(o.cwiseAbs());
    linear.push_back(o[0] + std::ptrdiff_t(d[0]) * (o[1] + std::ptrdiff_t(d[1]) * o[2]));
  }
  tbb::parallel_for(0, d[2], [&](int k) {
    for (int j = 0; j < d[1]; ++j) {
      const bool row_inside = k >= reach[2] && k < d[2] - reach[2] && j >= reach[1] && j < d[1] - reach[1];
      for (int i = 0; i < d[0]; ++i) {
        const std::size_t x = m.geom.linear(i, j, k);
        bool hit = m.data[x] == value;
        if (!hit && row_inside && i >= reach[0] && i < d[0] - reach[0]) {
          // Away from the border: plain offsets, no bounds checks.
          for (std::size_t o = 0; !hit && o < linear.size(); ++o) hit = m.data[x + linear[o]] == value;
        } else {
          for (std::size_t o = 0; !hit && o < offsets.size(); ++o) {
            const int a = i + offsets[o][0], b = j + offsets[o][1], c = k + offsets[o][2];
            // Outside the grid counts as background.
            hit = m.geom.contains(a, b, c) ? m.data[m.geom.linear(a, b, c)] == value : value == 0;
          }
        }
        out.data[x] = hit;
      }
    }
  });
  return out;
}

}  // namespace

Mask erode(const Mask& m, double radius_mm) {
  const auto offsets = ball_offsets(m.geom, radius_mm);
  Mask out = same_grid(m);
  if (!offsets.empty()) {
    const Mask near_background = stencil(m, offsets, 0);
    for (std::size_t i = 0; i < m.data.size(); ++i) out.data[i] = m.data[i] && !near_background.data[i];
    return out;
  }
  Mask background = same_grid(m);
  for (std::size_t i = 0; i < m.data.size(); ++i) background.data[i] = !m.data[i];
  const auto d2 = squared_distance_mm2(background);
  const float r2 = static_cast<float>(radius_mm * radius_mm);
  for (std::size_t i = 0; i < m.data.size(); ++i) out.data[i] = m.data[i] && d2[i] > r2;
  return out;
}

Mask dilate(const Mask& m, double radius_mm) {
  const auto offsets = ball_offsets(m.geom, radius_mm);
  if (!offsets.empty()) return stencil(m, offsets, 1);
  const auto d2 = squared_distance_mm2(m);
  Mask out = same_grid(m);
  const float r2 = static_cast<float>(radius_mm * radius_mm);
  for (std::size_t i = 0; i < m.data.size(); ++i) out.data[i] = d2[i] <= r2;
  return out;
}

std::vector<std::int32_t> label_components(const Mask& m, std::vector<std::int64_t>& sizes) {
  const auto& g = m.geom;
  const std::size_t n = m.data.size();
  // Union-find over foreground voxels, linking each to its -i, -j, -k neighbours; labels[] holds
  // the parent links first and the final labels at the end.
  std::vector<std::int32_t> labels(n, -1);
  auto find = [&](std::int32_t x) {
    while (labels[x] != x) {
      labels[x] = labels[labels[x]];
      x = labels[x];
    }
    return x;
  };
  auto unite = [&](std::int32_t a, std::int32_t b) {
    a = find(a);
    b = find(b);
    if (a != b) labels[std::max(a, b)] = std::min(a, b);
  };
  const std::int32_t sj = g.dims[0], sk = g.dims[0] * g.dims[1];
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j) {
      const std::int32_t row = k * sk + j * sj;
      for (int i = 0; i < g.dims[0]; ++i) {
        const std::int32_t x = row + i;
        if (!m.data[x]) continue;
        // Runs along i share the previous voxel's root: link directly.
        labels[x] = (i > 0 && m.data[x - 1]) ? labels[x - 1] : x;
        if (j > 0 && m.data[x - sj]) unite(x, x - sj);
        if (k > 0 && m.data[x - sk]) unite(x, x - sk);
      }
    }
  // Flatten every link to its root (a root is the smallest index of its set, so it comes first
  // and still points at itself), then give roots provisional ids in scan order, stored as
  // -2 - id in the root's entry, and count members.
  for (std::size_t x = 0; x < n; ++x)
    if (labels[x] >= 0) labels[x] = find(static_cast<std::int32_t>(x));
  std::vector<std::int64_t> count;
  for (std::size_t x = 0; x < n; ++x) {
    const std::int32_t r = labels[x];
    if (r == -1) continue;
    if (r == static_cast<std::int32_t>(x)) {
      labels[x] = -2 - static_cast<std::int32_t>(count.size());
      count.push_back(1);
    } else {
      labels[x] = labels[r];  // the root's provisional id
      ++count[static_cast<std::size_t>(-2 - labels[r])];
    }
  }
  std::vector<std::int32_t> order(count.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](auto a, auto b) { return count[a] > count[b]; });
  std::vector<std::int32_t> final_label(count.size());
  sizes.assign(count.size() + 1, 0);
  for (std::size_t l = 0; l < order.size(); ++l) {
    final_label[order[l]] = static_cast<std::int32_t>(l + 1);
    sizes[l + 1] = count[order[l]];
  }
  for (std::size_t x = 0; x < n; ++x)
    labels[x] = labels[x] <= -2 ? final_label[static_cast<std::size_t>(-2 - labels[x])] : 0;
  return labels;
}

namespace {

// Flood fill of background from the seeds; returns the reached set.
void flood_background(const Mask& m, std::vector<std::uint8_t>& reached,
                      std::vector<std::int64_t>& stack, int ni, int nj, int nk,
                      std::int64_t base, bool slices_only) {
  const std::int64_t sj = ni, sk = std::int64_t(ni) * nj;
  while (!stack.empty()) {
    const std::int64_t x = stack.back();
    stack.pop_back();
    const std::int64_t local = x - base;
    const int k = static_cast<int>(local / sk);
    const int j = static_cast<int>((local % sk) / sj);
    const int i = static_cast<int>(local % sj);
    auto push = [&](std::int64_t y) {
      if (!m.data[y] && !reached[y]) { reached[y] = 1; stack.push_back(y); }
    };
    if (i > 0) push(x - 1);
    if (i + 1 < ni) push(x + 1);
    if (j > 0) push(x - sj);
    if (j + 1 < nj) push(x + sj);
    if (!slices_only) {
      if (k > 0) push(x - sk);
      if (k + 1 < nk) push(x + sk);
    }
  }
}

}  // namespace

void fill_enclosed_3d(Mask& m) {
  // Components of the background; those that touch the grid's border are the outside.
  Mask background;
  background.geom = m.geom;
  background.data.resize(m.data.size());
  for (std::size_t x = 0; x < m.data.size(); ++x) background.data[x] = !m.data[x];
  std::vector<std::int64_t> sizes;
  const auto labels = label_components(background, sizes);
  std::vector<std::uint8_t> outside(sizes.size(), 0);
  const auto& d = m.geom.dims;
  for (int k = 0; k < d[2]; ++k)
    for (int j = 0; j < d[1]; ++j) {
      const bool face = k == 0 || j == 0 || k == d[2] - 1 || j == d[1] - 1;
      for (int i = 0; i < d[0]; i += (face ? 1 : std::max(1, d[0] - 1)))
        outside[labels[m.geom.linear(i, j, k)]] = 1;
    }
  for (std::size_t x = 0; x < m.data.size(); ++x)
    if (!m.data[x] && !outside[labels[x]]) m.data[x] = 1;
}

void fill_enclosed_slices(Mask& m, int axis) {
  const auto& d = m.geom.dims;
  const int a1 = axis == 0 ? 1 : 0, a2 = axis == 2 ? 1 : 2;  // in-plane axes, a1 < a2
  const std::int64_t stride[3] = {1, d[0], std::int64_t(d[0]) * d[1]};
  const int n1 = d[a1], n2 = d[a2];
  tbb::parallel_for(0, d[axis], [&](int s) {
    // A slice-local copy, so threads share no buffers.
    Mask slice;
    slice.geom.dims = {n1, n2, 1};
    slice.data.resize(std::size_t(n1) * n2);
    auto global = [&](int u, int v) { return s * stride[axis] + u * stride[a1] + v * stride[a2]; };
    for (int v = 0; v < n2; ++v)
      for (int u = 0; u < n1; ++u) slice.data[std::size_t(v) * n1 + u] = m.data[global(u, v)];
    std::vector<std::uint8_t> seen(slice.data.size(), 0);
    std::vector<std::int64_t> stack;
    for (int v = 0; v < n2; ++v)
      for (int u = 0; u < n1; ++u) {
        if (!(u == 0 || v == 0 || u == n1 - 1 || v == n2 - 1)) continue;
        const std::int64_t x = std::int64_t(v) * n1 + u;
        if (!slice.data[x] && !seen[x]) { seen[x] = 1; stack.push_back(x); }
      }
    flood_background(slice, seen, stack, n1, n2, 1, 0, true);
    for (int v = 0; v < n2; ++v)
      for (int u = 0; u < n1; ++u) {
        const std::int64_t x = std::int64_t(v) * n1 + u;
        if (!slice.data[x] && !seen[x]) m.data[global(u, v)] = 1;
      }
  });
}

}  // namespace caps

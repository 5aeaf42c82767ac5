#include "caps/volume/metal.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "caps/volume/morphology.hpp"
#include "caps/volume/segment.hpp"

namespace caps {

bool MetalRegion::in_slab(const Eigen::Vector3d& p) const {
  if (!found) return false;
  const double s = geom.lps_to_index(p)[slice_axis];
  for (const auto& [first, last] : slabs)
    if (s >= first - 0.5 && s <= last + 0.5) return true;
  return false;
}

MetalRegion detect_metal(const Volume& v, const MetalOptions& o) {
  MetalRegion m;
  m.geom = v.geom;
  m.threshold_hu = o.threshold_hu;
  m.slice_axis = superior_axis(v.geom);
  if (!o.detect || v.modality != Modality::CT || v.data.empty()) return m;
  m.checked = true;
  Mask hot;
  hot.geom = v.geom;
  hot.data.resize(v.data.size());
  bool any = false;
  for (std::size_t i = 0; i < v.data.size(); ++i) {
    hot.data[i] = v.data[i] >= o.threshold_hu;
    any = any || hot.data[i];
  }
  if (!any) return m;
  std::vector<std::int64_t> sizes;
  const auto labels = label_components(hot, sizes);
  const int n = static_cast<int>(sizes.size());
  const double voxel_mm3 = v.geom.spacing_mm.prod();
  std::vector<Eigen::Vector3i> lo(n, v.geom.dims), hi(n, Eigen::Vector3i::Constant(-1));
  std::vector<float> peak(n, -1e30f);
  const auto& d = v.geom.dims;
  for (int k = 0; k < d[2]; ++k)
    for (int j = 0; j < d[1]; ++j)
      for (int i = 0; i < d[0]; ++i) {
        const auto l = labels[v.geom.linear(i, j, k)];
        if (l <= 0) continue;
        peak[l] = std::max(peak[l], v.data[v.geom.linear(i, j, k)]);
        lo[l] = lo[l].cwiseMin(Eigen::Vector3i(i, j, k));
        hi[l] = hi[l].cwiseMax(Eigen::Vector3i(i, j, k));
      }
  std::vector<char> keep(n, 0);
  std::vector<std::pair<int, int>> ranges;
  const int sa = m.slice_axis;
  const int margin = std::max(1, static_cast<int>(std::ceil(o.margin_mm / v.geom.spacing_mm[sa] - 1e-9)));
  for (int l = 1; l < n; ++l) {
    const double mm3 = sizes[l] * voxel_mm3;
    const Eigen::Vector3d extent =
        (hi[l] - lo[l] + Eigen::Vector3i::Ones()).cast<double>().cwiseProduct(v.geom.spacing_mm);
    if (peak[l] < o.peak_hu || mm3 < o.min_mm3 || mm3 > o.max_ml * 1000.0 ||
        extent.maxCoeff() > o.max_extent_mm)
      continue;
    keep[l] = 1;
    ++m.components;
    m.voxels += static_cast<std::size_t>(sizes[l]);
    m.volume_mm3 += mm3;
    ranges.emplace_back(std::max(0, lo[l][sa] - margin), std::min(d[sa] - 1, hi[l][sa] + margin));
  }
  if (m.components == 0) return m;
  m.found = true;
  // The centre is the largest piece's (the bright streaks next to the metal can reach the
  // threshold too, in small pieces).
  int largest = 0;
  for (int l = 1; l < n && !largest; ++l)
    if (keep[l]) largest = l;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  m.max_hu = o.threshold_hu;
  for (int k = 0; k < d[2]; ++k)
    for (int j = 0; j < d[1]; ++j)
      for (int i = 0; i < d[0]; ++i) {
        const std::size_t x = v.geom.linear(i, j, k);
        if (labels[x] <= 0 || !keep[labels[x]]) continue;
        m.max_hu = std::max(m.max_hu, static_cast<double>(v.data[x]));
        if (labels[x] != largest) continue;
        sum += v.index_to_lps(Eigen::Vector3d(i, j, k));
      }
  m.centre_lps = sum / static_cast<double>(sizes[largest]);
  std::sort(ranges.begin(), ranges.end());
  for (const auto& r : ranges) {
    if (!m.slabs.empty() && r.first <= m.slabs.back().second + 1)
      m.slabs.back().second = std::max(m.slabs.back().second, r.second);
    else
      m.slabs.push_back(r);
  }
  // The slabs' S extent, at the grid's centre.
  Eigen::Vector3d centre = 0.5 * (v.geom.dims.cast<double>() - Eigen::Vector3d::Ones());
  m.z_min_mm = 1e300;
  m.z_max_mm = -1e300;
  for (const auto& [first, last] : m.slabs)
    for (double s : {first - 0.5, last + 0.5}) {
      centre[sa] = s;
      const double z = v.index_to_lps(centre)[2];
      m.z_min_mm = std::min(m.z_min_mm, z);
      m.z_max_mm = std::max(m.z_max_mm, z);
    }
  return m;
}

Volume repair_metal_slices(const Volume& v, const MetalRegion& m) {
  Volume out = v;
  if (!m.found) return out;
  const auto& d = v.geom.dims;
  const int sa = m.slice_axis;
  const int a1 = sa == 0 ? 1 : 0, a2 = sa == 2 ? 1 : 2;  // the in-slice axes
  auto index = [&](int s, int u, int w) {
    Eigen::Vector3i ijk;
    ijk[sa] = s;
    ijk[a1] = u;
    ijk[a2] = w;
    return v.geom.linear(ijk[0], ijk[1], ijk[2]);
  };
  for (const auto& [first, last] : m.slabs) {
    const int below = first - 1, above = last + 1;
    if (below < 0 && above >= d[sa]) continue;  // nothing clean to bridge from
    tbb::parallel_for(first, last + 1, [&](int s) {
      const double t = below < 0 ? 1.0 : above >= d[sa] ? 0.0
                                                       : double(s - below) / double(above - below);
      for (int w = 0; w < d[a2]; ++w)
        for (int u = 0; u < d[a1]; ++u) {
          const float lo = below >= 0 ? v.data[index(below, u, w)] : 0.0f;
          const float hi = above < d[sa] ? v.data[index(above, u, w)] : 0.0f;
          out.data[index(s, u, w)] = static_cast<float>((1.0 - t) * lo + t * hi);
        }
    });
  }
  return out;
}

}  // namespace caps

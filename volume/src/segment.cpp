#include "caps/volume/segment.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "caps/core/error.hpp"
#include "caps/core/reporter.hpp"
#include "caps/volume/morphology.hpp"

namespace caps {
namespace {

// Block means over f_i x f_j x f_k voxels; the geometry keeps the block centres.
Volume downsample(const Volume& v, const Eigen::Vector3i& f) {
  if (f == Eigen::Vector3i::Ones()) return v;
  Volume w;
  w.modality = v.modality;
  w.source = v.source;
  w.format = v.format;
  w.geom = v.geom;
  for (int a = 0; a < 3; ++a) {
    w.geom.dims[a] = std::max(1, v.geom.dims[a] / f[a]);
    w.geom.spacing_mm[a] = v.geom.spacing_mm[a] * f[a];
  }
  w.geom.origin_lps = v.index_to_lps(0.5 * (f.cast<double>() - Eigen::Vector3d::Ones()));
  w.data.assign(w.geom.n_voxels(), 0.0f);
  const float inv = 1.0f / static_cast<float>(f.prod());
  tbb::parallel_for(0, w.geom.dims[2], [&](int k) {
    for (int j = 0; j < w.geom.dims[1]; ++j)
      for (int i = 0; i < w.geom.dims[0]; ++i) {
        float sum = 0;
        for (int c = 0; c < f[2]; ++c)
          for (int b = 0; b < f[1]; ++b)
            for (int a = 0; a < f[0]; ++a)
              sum += v.at(i * f[0] + a, j * f[1] + b, k * f[2] + c);
        w.at(i, j, k) = sum * inv;
      }
  });
  return w;
}

Mask threshold(const Volume& v, double t) {
  Mask m;
  m.geom = v.geom;
  m.data.resize(v.data.size());
  for (std::size_t i = 0; i < v.data.size(); ++i) m.data[i] = v.data[i] >= t;
  return m;
}

double voxel_ml(const VolumeGeometry& g) { return g.spacing_mm.prod() * 1e-3; }

Mask keep_label(const std::vector<std::int32_t>& labels, const VolumeGeometry& g,
                std::int32_t keep) {
  Mask m;
  m.geom = g;
  m.data.resize(labels.size());
  for (std::size_t i = 0; i < labels.size(); ++i) m.data[i] = labels[i] == keep;
  return m;
}

// Keeps the head: the largest object above threshold, cut loose from thin attachments (table,
// head holder, wrapping) by an opening, with small cut-off pieces (ear rims) put back.
// Fills air enclosed by the head: per slice across the superior axis (airway, nostrils, mouth,
// which open to the outside only downwards), then in 3-D (sinuses).
void fill_enclosed(Mask& m) {
  fill_enclosed_slices(m, superior_axis(m.geom));
  fill_enclosed_3d(m);
}

// The voxel box [lo, hi] of a label, grown by `margin` voxels and clamped to the grid.
void label_box(const std::vector<std::int32_t>& labels, const VolumeGeometry& g, std::int32_t label,
               int margin, Eigen::Vector3i& lo, Eigen::Vector3i& hi) {
  lo = g.dims;
  hi = Eigen::Vector3i::Constant(-1);
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i)
        if (labels[g.linear(i, j, k)] == label) {
          lo = lo.cwiseMin(Eigen::Vector3i(i, j, k));
          hi = hi.cwiseMax(Eigen::Vector3i(i, j, k));
        }
  lo = (lo.array() - margin).max(0).matrix();
  hi = (hi.array() + margin).min(g.dims.array() - 1).matrix();
}

// The sub-grid [lo, hi] of a grid, with the same physical positions.
VolumeGeometry sub_geometry(const VolumeGeometry& g, const Eigen::Vector3i& lo,
                            const Eigen::Vector3i& hi) {
  VolumeGeometry c = g;
  c.dims = hi - lo + Eigen::Vector3i::Ones();
  c.origin_lps = g.index_to_lps(lo.cast<double>());
  return c;
}

template <typename T, typename F>
std::vector<T> crop_values(const VolumeGeometry& g, const Eigen::Vector3i& lo,
                           const VolumeGeometry& c, F&& value) {
  std::vector<T> out(c.n_voxels());
  tbb::parallel_for(0, c.dims[2], [&](int k) {
    for (int j = 0; j < c.dims[1]; ++j)
      for (int i = 0; i < c.dims[0]; ++i)
        out[c.linear(i, j, k)] = value(g.linear(i + lo[0], j + lo[1], k + lo[2]));
  });
  return out;
}

// Finds the head (the largest object above the threshold), and crops the working volume to its
// box so that the rest of the segmentation works on the head only.
Mask find_head(const Mask& raw, const SegmentOptions& o, Segmentation& seg) {
  std::vector<std::int64_t> sizes;
  const auto labels = label_components(raw, sizes);
  const double ml = voxel_ml(raw.geom);
  if (sizes.size() < 2)
    throw InvalidInput(cat(seg.working.source, ": no head found: no voxel is above the skin "
                           "threshold ", seg.skin_threshold, "; check --skin-threshold and that "
                           "the file is a head scan"));
  constexpr double kMinHeadMl = 100.0;
  if (sizes[1] * ml < kMinHeadMl)
    throw InvalidInput(cat(seg.working.source, ": no head found: the largest object above ",
                           seg.skin_threshold, " is only ", sizes[1] * ml, " ml (a head is over ",
                           kMinHeadMl, " ml); check --skin-threshold and that the file is a head "
                           "scan"));
  for (std::size_t l = 2; l < sizes.size(); ++l) seg.detached_volume_ml += sizes[l] * ml;
  const int margin = 2 + static_cast<int>(std::ceil(std::max(o.detach_radius_mm, o.bone_closing_mm) /
                                                    raw.geom.spacing_mm.minCoeff()));
  Eigen::Vector3i lo, hi;
  label_box(labels, raw.geom, 1, margin, lo, hi);
  const VolumeGeometry box = sub_geometry(raw.geom, lo, hi);
  const Volume& w = seg.working;
  Volume cropped;
  cropped.geom = box;
  cropped.modality = w.modality;
  cropped.source = w.source;
  cropped.format = w.format;
  cropped.data = crop_values<float>(raw.geom, lo, box, [&](std::size_t x) { return w.data[x]; });
  seg.working = std::move(cropped);
  Mask head;
  head.geom = box;
  head.data = crop_values<std::uint8_t>(raw.geom, lo, box,
                                        [&](std::size_t x) -> std::uint8_t { return labels[x] == 1; });
  return head;
}

// Cuts the head loose from what touches it only thinly (table, head holder, wrapping) by an
// opening, putting small cut-off pieces (ear rims) back.
Mask clean_skin(Mask head, const SegmentOptions& o, Segmentation& seg) {
  const double ml = voxel_ml(head.geom);
  // Fill before opening: in MR the bright scalp is a shell a few mm thick over dark bone, which
  // an opening would otherwise cut away as if it were an attachment.
  fill_enclosed(head);
  const Mask core = erode(head, o.detach_radius_mm);
  std::vector<std::int64_t> core_sizes;
  const auto core_labels = label_components(core, core_sizes);
  if (core_sizes.size() < 2) return head;  // too thin to open: keep as is
  const Mask body = dilate(keep_label(core_labels, head.geom, 1), o.detach_radius_mm);
  Mask cut = head;
  for (std::size_t i = 0; i < cut.data.size(); ++i) cut.data[i] = head.data[i] && !body.data[i];
  std::vector<std::int64_t> cut_sizes;
  const auto cut_labels = label_components(cut, cut_sizes);
  Mask kept = head;
  std::vector<char> put_back(cut_sizes.size(), 0);
  for (std::size_t l = 1; l < cut_sizes.size(); ++l) {
    if (cut_sizes[l] * ml < o.detach_keep_ml) {
      put_back[l] = 1;
    } else {
      ++seg.detached_pieces;
      seg.detached_volume_ml += cut_sizes[l] * ml;
    }
  }
  for (std::size_t i = 0; i < kept.data.size(); ++i)
    if (cut_labels[i] > 0 && !put_back[cut_labels[i]]) kept.data[i] = 0;
  // Removing a piece can leave crumbs that no longer touch the head.
  std::vector<std::int64_t> final_sizes;
  const auto final_labels = label_components(kept, final_sizes);
  Mask result = keep_label(final_labels, head.geom, 1);
  for (std::size_t l = 2; l < final_sizes.size(); ++l) seg.detached_volume_ml += final_sizes[l] * ml;
  return result;
}

Mask clean_bone(const Mask& raw, const Mask& skin, const SegmentOptions& o) {
  Mask b = raw;
  for (std::size_t i = 0; i < b.data.size(); ++i) b.data[i] = b.data[i] && skin.data[i];
  if (o.bone_closing_mm > 0) b = erode(dilate(b, o.bone_closing_mm), o.bone_closing_mm);
  std::vector<std::int64_t> sizes;
  const auto labels = label_components(b, sizes);
  Mask out;
  out.geom = b.geom;
  out.data.assign(b.data.size(), 0);
  if (sizes.size() < 2) return out;
  const double keep = o.bone_keep_fraction * static_cast<double>(sizes[1]);
  for (std::size_t i = 0; i < labels.size(); ++i)
    out.data[i] = labels[i] > 0 && static_cast<double>(sizes[labels[i]]) >= keep;
  return out;
}

Mask resample_mask(const Volume& src, const VolumeGeometry& g) {
  Mask m;
  m.geom = g;
  m.data.assign(g.n_voxels(), 0);
  tbb::parallel_for(0, g.dims[2], [&](int k) {
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i) {
        const Eigen::Vector3d q = src.lps_to_index(g.index_to_lps(Eigen::Vector3d(i, j, k)));
        const Eigen::Vector3i n = q.array().round().cast<int>();
        if (src.geom.contains(n[0], n[1], n[2]) && src.at(n[0], n[1], n[2]) != 0.0f)
          m.data[g.linear(i, j, k)] = 1;
      }
  });
  return m;
}

}  // namespace

int superior_axis(const VolumeGeometry& g) {
  int best = 2;
  double best_dot = -1;
  for (int a = 0; a < 3; ++a) {
    const double d = std::abs(g.direction(2, a));
    if (d > best_dot) { best_dot = d; best = a; }
  }
  return best;
}

double otsu_threshold(const Volume& v) {
  const auto [lo_it, hi_it] = std::minmax_element(v.data.begin(), v.data.end());
  const double lo = *lo_it, hi = *hi_it;
  if (!(hi > lo)) return lo;
  constexpr int kBins = 256;
  std::vector<double> hist(kBins, 0.0);
  for (float x : v.data) {
    const int b = std::min(kBins - 1, static_cast<int>((x - lo) / (hi - lo) * kBins));
    hist[b] += 1.0;
  }
  const double total = static_cast<double>(v.data.size());
  double sum_all = 0;
  for (int b = 0; b < kBins; ++b) sum_all += b * hist[b];
  double w0 = 0, sum0 = 0, best = -1;
  int best_bin = 0;
  for (int b = 0; b < kBins; ++b) {
    w0 += hist[b];
    sum0 += b * hist[b];
    const double w1 = total - w0;
    if (w0 == 0 || w1 == 0) continue;
    const double m0 = sum0 / w0, m1 = (sum_all - sum0) / w1;
    const double between = w0 * w1 * (m0 - m1) * (m0 - m1);
    if (between > best) { best = between; best_bin = b; }
  }
  return lo + (best_bin + 1) * (hi - lo) / kBins;
}

Segmentation segment_head(const Volume& v, const SegmentOptions& o, Reporter* reporter) {
  if (!(o.working_voxel_mm > 0 && o.working_voxel_mm <= 10))
    throw InvalidInput(cat("segmentation: working voxel ", o.working_voxel_mm,
                           " mm must be in (0, 10]"));
  if (!(o.detach_radius_mm >= 0 && o.detach_radius_mm <= 20))
    throw InvalidInput(cat("segmentation: detach radius ", o.detach_radius_mm,
                           " mm must be in [0, 20]"));
  const auto [lo, hi] = std::minmax_element(v.data.begin(), v.data.end());
  if (!(*hi - *lo > 1e-3f * std::max(1.0f, std::abs(*hi))))
    throw InvalidInput(cat(v.source, ": no head found: the image is uniform (every voxel is ", *lo,
                           "); check that the file holds the scan"));
  Progress progress(reporter, "segmenting skin and bone", 4);
  Segmentation seg;
  Eigen::Vector3i factor;
  for (int a = 0; a < 3; ++a)
    factor[a] = std::max(1, static_cast<int>(std::floor(o.working_voxel_mm / v.geom.spacing_mm[a] + 0.25)));
  // Metal (CT): the slices through it are bridged from the clean slices around, so the masks
  // carry neither the metal nor its streaks (metal.hpp).
  seg.metal = detect_metal(v, o.metal);
  Volume repaired;
  if (seg.metal.found) {
    repaired = repair_metal_slices(v, seg.metal);
    seg.notes.push_back(cat("metal streaks removed from the slices at S ",
                            std::round(seg.metal.z_min_mm * 10) / 10, " .. ",
                            std::round(seg.metal.z_max_mm * 10) / 10, " mm before segmenting"));
  }
  seg.working = downsample(seg.metal.found ? repaired : v, factor);
  if (factor != Eigen::Vector3i::Ones())
    seg.notes.push_back(cat("segmented on ", factor[0], "x", factor[1], "x", factor[2],
                            " voxel blocks (", seg.working.geom.spacing_mm.transpose(), " mm)"));
  const bool ct = v.modality == Modality::CT;
  if (o.skin_threshold) {
    seg.skin_threshold = *o.skin_threshold;
    seg.skin_method = cat("threshold ", seg.skin_threshold, ct ? " HU (given)" : " (given)");
  } else if (ct) {
    seg.skin_threshold = -400.0;
    seg.skin_method = "threshold -400 HU";
  } else {
    seg.skin_threshold = otsu_threshold(seg.working);
    seg.skin_method = cat("Otsu threshold ", seg.skin_threshold);
  }
  const Mask raw_skin = threshold(seg.working, seg.skin_threshold);
  progress.update(1);
  seg.skin = clean_skin(find_head(raw_skin, o, seg), o, seg);
  fill_enclosed(seg.skin);
  seg.head_volume_ml = seg.skin.count() * voxel_ml(seg.skin.geom);
  if (seg.detached_pieces > 0)
    seg.notes.push_back(cat("cut away ", seg.detached_pieces, " attached object(s), ",
                            std::round(seg.detached_volume_ml), " ml (table, head holder, wrapping)"));
  progress.update(2);

  seg.bone_threshold = std::numeric_limits<double>::quiet_NaN();
  if (o.bone_mask) {
    seg.bone = resample_mask(*o.bone_mask, seg.working.geom);
    for (std::size_t i = 0; i < seg.bone.data.size(); ++i)
      seg.bone.data[i] = seg.bone.data[i] && seg.skin.data[i];
    seg.bone_method = cat("mask ", o.bone_mask->source);
    if (seg.bone.count() == 0)
      throw InvalidInput(cat(o.bone_mask->source, ": the bone mask has no voxel inside the head; "
                             "check that it belongs to this scan (same patient frame)"));
  } else if (ct || o.bone_threshold) {
    seg.bone_threshold = o.bone_threshold ? *o.bone_threshold : 250.0;
    seg.bone_method = cat("threshold ", seg.bone_threshold, ct ? " HU" : "",
                          o.bone_threshold ? " (given)" : "");
    seg.bone = clean_bone(threshold(seg.working, seg.bone_threshold), seg.skin, o);
  } else {
    seg.bone_is_approximate = true;
    seg.bone = erode(seg.skin, o.mr_scalp_mm);
    seg.bone_method = cat("approximation: skin envelope moved inward ", o.mr_scalp_mm,
                          " mm (no bone signal in MR; pass --bone-mask for a measured map)");
    warn(reporter, cat(v.source, ": MR has no reliable bone signal; bone approximated as the skin moved "
             "inward ", o.mr_scalp_mm, " mm. Pass --bone-mask for a measured thickness."));
  }
  seg.bone_volume_ml = seg.bone.count() * voxel_ml(seg.bone.geom);
  progress.update(4);
  return seg;
}

}  // namespace caps

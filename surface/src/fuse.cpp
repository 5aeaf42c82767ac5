#include "caps/surface/fuse.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <vector>

#include "caps/core/error.hpp"
#include "caps/surface/range_mesh.hpp"
#include "caps/surface/register.hpp"
#include "caps/surface/scan_model.hpp"
#include "caps/volume/model.hpp"

namespace caps {

FusedModel fuse_scan(const ModelContent& ct, const ScanMesh& scan, const Eigen::Matrix4d& T,
                     const FuseOptions& o, Reporter* reporter) {
  if (!T.allFinite() || !(std::abs(T.topLeftCorner<3, 3>().determinant()) > 1e-12))
    throw InvalidInput("fuse: the scan-to-model transform must be finite and invertible");
  if (!(o.max_gap_mm > 0)) throw InvalidParameter(cat("{max_gap} ", o.max_gap_mm, " mm must be positive"));
  const bool has_texture = !scan.texture.rgb.empty() && scan.FUV.rows() == scan.mesh.n_faces();
  const bool has_vertex_colors = scan.vertex_colors.rows() == scan.mesh.n_vertices();
  if (!has_texture && !has_vertex_colors)
    throw InvalidInput(cat(scan.source, ": the scan has no colour (no texture with coordinates, "
                           "no vertex colours); give its texture with --texture"));
  const auto& g = ct.maps.grid;

  // The scan in LPS mm, measured on the CT's axis and grid by the scan importer's rays: up = S
  // and front = A make its file-to-LPS rotation the identity.
  ScanMesh lps = scan;
  lps.mesh.V = transform_points(T, scan.mesh.V);
  lps.mm_per_unit = 1.0;
  if (T.topLeftCorner<3, 3>().determinant() < 0) lps.mesh.F.col(1).swap(lps.mesh.F.col(2));
  ScanModelOptions so;
  so.thickness_mm = 1.0;  // unused: only r_skin and the colour are taken
  so.mm_per_unit = 1.0;
  so.up = {0, 0, 1};
  so.front = {0, -1, 0};
  so.maps.n_theta = g.n_theta;
  so.maps.n_z = g.n_z;
  so.axis = ct.maps.axis;
  so.grid = g;
  so.min_height_mm = 0;
  so.max_height_mm = 1e9;
  const ScanModel measured = build_scan_model(lps, so, reporter);

  FusedModel out;
  static_cast<ModelContent&>(out) = ct;
  CylindricalMaps& m = out.maps;
  const bool ct_color = !ct.color.rgb.empty();
  if (!ct_color) {
    out.color.width = g.n_theta;
    out.color.height = g.n_z;
    out.color.rgb.assign(g.size() * 3, 128);
  }
  std::vector<double> gaps;
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const std::size_t c = g.index(j, k);
      if (!measured.maps.measured_skin[c] || (measured.maps.flags[c] & kTruncated)) continue;
      const double delta = measured.maps.r_skin[c] - m.r_skin[c];
      if (std::abs(delta) > o.max_gap_mm) {
        ++out.gap_cells;
        continue;
      }
      gaps.push_back(std::abs(delta));
      ++out.colored_cells;
      // Colour images have superior on top: row n_z - 1 - k.
      const std::size_t px = (std::size_t(g.n_z - 1 - k) * g.n_theta + j) * 3;
      for (int q = 0; q < 3; ++q) out.color.rgb[px + q] = measured.color.rgb[px + q];
      if (!o.scan_skin) continue;
      const double t_old = m.thickness[c], t_new = std::max(0.0, t_old + delta);
      m.r_skin[c] = measured.maps.r_skin[c];
      m.thickness[c] = static_cast<float>(t_new);
      const double ratio = t_old > 0 ? t_new / t_old : 1.0;
      m.thickness_normal[c] = static_cast<float>(m.thickness_normal[c] * ratio);
      if (m.has_layers()) {
        for (auto* layer : {&m.thickness_skin, &m.thickness_fat, &m.thickness_deep})
          (*layer)[c] = static_cast<float>((*layer)[c] * ratio);
        for (auto* layer : {&m.thickness_skin_normal, &m.thickness_fat_normal, &m.thickness_deep_normal})
          if (!layer->empty()) (*layer)[c] = static_cast<float>((*layer)[c] * ratio);
      }
      ++out.skin_cells;
    }
  if (out.colored_cells == 0)
    throw InvalidInput(cat(scan.source, ": no part of the registered scan lies within ", o.max_gap_mm,
                           " mm of the model's skin; check the registration"));
  if (!gaps.empty()) {
    std::nth_element(gaps.begin(), gaps.begin() + gaps.size() / 2, gaps.end());
    out.median_gap_mm = gaps[gaps.size() / 2];
  }
  if (out.skin_cells > 0) {
    out.skin = range_mesh(m, RangeSurface::Skin, {true});
    out.stats = model_statistics(m);
  }
  if (out.gap_cells > out.colored_cells / 10)
    warn(reporter, cat("fuse: on ", out.gap_cells, " cells the scan lies more than ", o.max_gap_mm,
                       " mm off the CT's skin (hair, clothing, another expression?); the CT's "
                       "colour is kept there"));
  return out;
}

}  // namespace caps

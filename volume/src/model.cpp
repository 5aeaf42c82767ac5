#include "caps/volume/model.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "caps/core/error.hpp"
#include "caps/core/reporter.hpp"
#include "caps/core/units.hpp"
#include "caps/volume/isosurface.hpp"
#include "caps/volume/model_dir.hpp"
#include "json_vectors.hpp"

namespace fs = std::filesystem;
using nlohmann::json;

namespace caps {
namespace {

// The field whose `level` isosurface is the mask's boundary, placed on the intensities where
// they agree with the mask: inside the mask values are raised to at least level + 1, outside
// lowered to at most level - 1, so cut-away attachments and filled cavities vanish. A border of
// outside voxels closes the surface where the head is cut by the scan's field of view.
Volume masked_field(const Volume& intensity, const Mask& m, float level) {
  Volume f;
  f.geom = m.geom;
  f.geom.dims = m.geom.dims + Eigen::Vector3i::Constant(2);
  f.geom.origin_lps = m.geom.index_to_lps(Eigen::Vector3d::Constant(-1.0));
  f.data.assign(f.geom.n_voxels(), level - 1.0f);
  const auto& d = m.geom.dims;
  for (int k = 0; k < d[2]; ++k)
    for (int j = 0; j < d[1]; ++j)
      for (int i = 0; i < d[0]; ++i) {
        const std::size_t src = m.geom.linear(i, j, k);
        const float value = intensity.data.empty() ? (m.data[src] ? level + 1.0f : level - 1.0f)
                                                   : intensity.data[src];
        f.data[f.geom.linear(i + 1, j + 1, k + 1)] =
            m.data[src] ? std::max(value, level + 1.0f) : std::min(value, level - 1.0f);
      }
  return f;
}

TriMesh surface_of(const Volume& working, const Mask& m, double level, bool use_intensity,
                   const ModelOptions& o) {
  static const Volume kNoIntensity;
  TriMesh mesh = extract_isosurface(
      masked_field(use_intensity ? working : kNoIntensity, m, static_cast<float>(level)),
      static_cast<float>(level));
  if (o.smoothing_iterations > 0) smooth_taubin(mesh, o.smoothing_iterations);
  if (o.decimate_fraction < 1.0 && mesh.n_faces() > 0) mesh = decimate(mesh, o.decimate_fraction);
  return mesh;
}

double percentile(std::vector<double> xs, double p) {
  if (xs.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto k = static_cast<std::size_t>(std::clamp(p, 0.0, 1.0) * (xs.size() - 1));
  std::nth_element(xs.begin(), xs.begin() + k, xs.end());
  return xs[k];
}

// model.json's thickness.layers: how the tissue layers were measured, or why they were not.
json layers_json(const VolumeModel& m) {
  const LayerOptions& o = m.layer_options;
  if (m.maps.has_layers())
    return {{"measured", true},
            {"method", "fat = where the CT profile from skin to bone lies below the fat level; "
                       "interfaces where it crosses the level (sub-voxel), along the ray and along "
                       "the normal; see docs/volume.md"},
            {"fat_level_hu", o.fat_level_hu},
            {"merge_gap_mm", o.merge_gap_mm},
            {"min_band_mm", o.min_band_mm},
            {"fill", "cells with a layer flag: skin and fat filled from the measured cells' "
                     "proportions (fat 0 where none was seen), deep = thickness - skin - fat; "
                     "see layer_validity.nrrd"}};
  const std::string reason =
      !o.measure ? "not requested"
                 : cat(to_string(m.modality), ": fat is told apart by its CT number (HU); this "
                       "modality's intensities are not calibrated, so the layers are not measured");
  return {{"measured", false}, {"reason", reason}};
}

// model.json's thickness.base: how the base of the soft tissue (bone, or a cavity) was found.
json base_json(const VolumeModel& m) {
  const BoneOptions& o = m.bone_options;
  const auto& seg = m.segmentation;
  const bool ct = m.modality == Modality::CT;
  const bool edge = ct && std::isfinite(seg.bone_threshold) && o.method == BoneMethod::Edge;
  json j = {{"bone_method", edge ? "edge" : "threshold"},
            {"mask", seg.bone_method},
            {"cavity_base", ct && o.cavity_base},
            {"tissue_reach_mm", ct ? o.tissue_reach_mm : 0.0},
            {"bone_cap_mm", m.bone_cap_mm}};
  if (edge) {
    j["floor_hu"] = o.floor_hu;
    j["method"] = "bone: the first peak of the CT profile inward from the skin at least floor_hu "
                  "above the ray's soft-tissue level, confirmed laterally, its edge at half "
                  "maximum; the mask (bone.ply, the normal thickness) stays the threshold's; see "
                  "docs/volume.md";
  } else {
    j["method"] = "bone: the first voxel of the mask inward from the skin, its edge at half maximum";
  }
  if (ct && o.cavity_base)
    j["cavity"] = "no bone within the cap but an air cavity under the tissue (air, or 1 mm below "
                  "-200 HU: air at partial volume): the base is the cavity's edge (half maximum), "
                  "free (no support); a no_bone strip up to 3 cells wide between such cells (a "
                  "septum) too, its depth filled from them; validity flag 32 base_cavity";
  if (ct && o.tissue_reach_mm > 0)
    j["tissue"] = cat("neither bone nor an air cavity within the cap, the tissue going on deeper, "
                      "at most tissue_reach_mm over the skin from a measured base: the base lies at "
                      "the depth interpolated from the measured ones, free (no support); validity "
                      "flag 128 base_tissue");
  return j;
}

}  // namespace

ModelStatistics model_statistics(const CylindricalMaps& maps) {
  const auto& g = maps.grid;
  ModelStatistics s;
  s.cells = g.size();
  std::vector<double> t, tn, rs;
  for (std::size_t i = 0; i < g.size(); ++i) {
    const auto f = maps.flags[i];
    s.no_skin += (f & kNoSkin) != 0;
    s.no_bone += (f & kNoBone) != 0;
    s.undercut += (f & kUndercut) != 0;
    s.grazing += (f & kGrazing) != 0;
    s.truncated += (f & kTruncated) != 0;
    s.eye += (f & kEye) != 0;
    if (maps.measured_skin[i]) rs.push_back(maps.r_skin[i]);
    if (!flags_valid(f)) continue;
    s.base_cavity += (f & kBaseCavity) != 0;
    s.base_tissue += (f & kBaseTissue) != 0;
    ++s.valid_cells;
    if (!maps.measured_bone[i]) continue;  // an interpolated depth is no measurement
    t.push_back(maps.thickness[i]);
    tn.push_back(maps.thickness_normal[i]);
  }
  if (!t.empty()) {
    s.thickness_mean_mm = std::accumulate(t.begin(), t.end(), 0.0) / t.size();
    s.thickness_median_mm = percentile(t, 0.5);
    s.thickness_p5_mm = percentile(t, 0.05);
    s.thickness_p95_mm = percentile(t, 0.95);
    s.thickness_normal_median_mm = percentile(tn, 0.5);
  }
  s.r_skin_median_mm = percentile(rs, 0.5);
  if (maps.has_layers()) {
    std::vector<double> skin, fat, deep;
    for (std::size_t i = 0; i < g.size(); ++i) {
      const auto f = maps.layer_flags[i];
      s.no_fat += (f & kLayerNoFat) != 0;
      s.several_fat_bands += (f & kLayerSeveralBands) != 0;
      if (f != 0) continue;
      skin.push_back(maps.thickness_skin[i]);
      fat.push_back(maps.thickness_fat[i]);
      deep.push_back(maps.thickness_deep[i]);
    }
    s.layer_cells = skin.size();
    if (!skin.empty()) {
      s.skin_layer_median_mm = percentile(skin, 0.5);
      s.fat_median_mm = percentile(fat, 0.5);
      s.deep_median_mm = percentile(deep, 0.5);
    }
  }
  // The face. A head is nearly mirror-symmetric about its mid-sagittal plane, which meets the
  // cylinder in two meridians (front and back); of those, the front is the one with the most
  // prominent bump (the nose) over its surroundings 20 degrees to either side. Ears are paired
  // and off the meridians, so they cannot be taken for the face.
  auto usable = [&](std::size_t c) {
    return maps.measured_skin[c] && !(maps.flags[c] & (kGrazing | kTruncated | kUndercut));
  };
  auto r_at = [&](int j, int k) { return maps.r_skin[g.index((j % g.n_theta + g.n_theta) % g.n_theta, k)]; };
  auto ok_at = [&](int j, int k) { return usable(g.index((j % g.n_theta + g.n_theta) % g.n_theta, k)); };
  int best_j = 0;
  double best_score = std::numeric_limits<double>::max();
  const int quarter = g.n_theta / 4;
  for (int j0 = 0; j0 < g.n_theta / 2; ++j0) {
    double sum = 0;
    int n = 0;
    for (int k = 0; k < g.n_z; k += 2)
      for (int d = 2; d <= quarter; d += 2) {
        for (int side : {j0, j0 + g.n_theta / 2}) {
          if (!ok_at(side + d, k) || !ok_at(side - d, k)) continue;
          sum += std::abs(r_at(side + d, k) - r_at(side - d, k));
          ++n;
        }
      }
    if (n > 0 && sum / n < best_score) { best_score = sum / n; best_j = j0; }
  }
  const int half = std::max(1, static_cast<int>(std::lround(20.0 / g.dtheta_deg())));
  double best_prominence = -1e300;
  for (int j0 : {best_j, best_j + g.n_theta / 2})
    for (int k = 0; k < g.n_z; ++k)
      for (int dj = -2; dj <= 2; ++dj) {
        const int j = j0 + dj;
        if (!ok_at(j, k) || !ok_at(j + half, k) || !ok_at(j - half, k)) continue;
        const double prominence = r_at(j, k) - 0.5 * (r_at(j + half, k) + r_at(j - half, k));
        if (prominence > best_prominence) {
          best_prominence = prominence;
          s.face_theta_deg = g.theta_deg((j % g.n_theta + g.n_theta) % g.n_theta);
          s.face_z_mm = g.z_mm(k);
        }
      }
  std::vector<double> forehead;
  for (int k = 0; k < g.n_z; ++k) {
    const double dz = g.z_mm(k) - s.face_z_mm;
    if (dz < 30 || dz > 60) continue;
    for (int j = 0; j < g.n_theta; ++j) {
      const double th = g.theta_deg(j) - s.face_theta_deg;
      if (std::abs(th) <= 15 && flags_valid(maps.flags[g.index(j, k)]))
        forehead.push_back(maps.thickness[g.index(j, k)]);
    }
  }
  s.forehead_thickness_mm = percentile(forehead, 0.5);
  return s;
}

namespace {

// A CT stored unsigned (HU + 1024, as the Stanford CThead is) has its air near 0 instead of
// -1000: every threshold would then miss. Seen on a sample of the voxels (air fills most of a
// head CT's field of view): the lowest value at or above -50 with values beyond +1000.
bool looks_unsigned_ct(const Volume& v) {
  if (v.modality != Modality::CT || v.data.empty()) return false;
  float lo = v.data[0], hi = v.data[0];
  for (std::size_t i = 0; i < v.data.size(); i += 61) {
    lo = std::min(lo, v.data[i]);
    hi = std::max(hi, v.data[i]);
  }
  return lo >= -50.0f && hi > 1000.0f;
}

}  // namespace

VolumeModel build_volume_model(const Volume& input, const ModelOptions& o, Reporter* reporter) {
  Volume shifted;
  if (looks_unsigned_ct(input)) {
    shifted = input;
    for (float& x : shifted.data) x -= 1024.0f;
    warn(reporter, cat(input.source, ": the CT's air lies near 0 instead of -1000 HU: read as "
                       "unsigned values (HU + 1024) and shifted by -1024 HU; check the file's "
                       "rescale intercept"));
  }
  const Volume& read = shifted.data.empty() ? input : shifted;
  // Metal (CT): its streaks are removed from the slices through it before anything is measured;
  // the cells whose skin lies there are marked by cylindrical_maps().
  const MetalRegion metal = detect_metal(read, o.segment.metal);
  Volume repaired;
  if (metal.found) repaired = repair_metal_slices(read, metal);
  const Volume& v = metal.found ? repaired : read;
  VolumeModel m;
  m.metal = metal;
  m.source = v.source;
  m.source_format = v.format;
  m.modality = v.modality;
  m.source_dims = v.geom.dims;
  m.source_spacing_mm = v.geom.spacing_mm;
  m.notes = v.notes;
  m.segmentation = segment_head(v, o.segment, reporter);
  // A skull-stripped MR (brain extraction) keeps only the brain: its "skin" would be the brain's
  // surface, its landmarks on the brain. Refused (it was a warning, and the model was built).
  if (v.modality != Modality::CT && m.segmentation.head_volume_ml < o.min_head_ml)
    throw InvalidInput(cat(v.source, ": the head's volume is only ",
                           std::lround(m.segmentation.head_volume_ml), " ml, that of a brain: the "
                           "scan looks skull-stripped, and its \"skin\" would be the brain's "
                           "surface; use the scan before brain extraction (if it is a whole head, "
                           "a small child's, give --min-head-ml 0)"));
  const CylinderAxis axis = o.axis ? *o.axis : fit_axis(m.segmentation);
  if (metal.found) {
    MapOptions mo = o.maps;
    mo.metal = metal;
    m.maps = cylindrical_maps(v, m.segmentation, axis, mo, reporter);
  } else {
    m.maps = cylindrical_maps(v, m.segmentation, axis, o.maps, reporter);
  }
  m.layer_options = o.maps.layers;
  m.bone_options = o.maps.bone;
  m.bone_cap_mm = o.maps.bone_cap_mm;
  m.stats = model_statistics(m.maps);
  if (o.surfaces) {
    Progress progress(reporter, "extracting skin and bone surfaces", 2);
    const auto& seg = m.segmentation;
    m.skin = surface_of(seg.working, seg.skin, seg.skin_threshold, true, o);
    progress.update(1);
    const bool bone_by_threshold = std::isfinite(seg.bone_threshold);
    m.bone = surface_of(seg.working, seg.bone, bone_by_threshold ? seg.bone_threshold : 0.5,
                        bone_by_threshold, o);
  }
  for (const auto& n : m.segmentation.notes) m.notes.push_back(n);
  if (metal.found) {
    const MetalCells cells = metal_cells(m.maps);
    const auto mm = [](double x) { return std::round(10 * x) / 10; };
    std::size_t slices = 0;
    for (const auto& [first, last] : metal.slabs) slices += static_cast<std::size_t>(last - first + 1);
    warn(reporter, cat(v.source, ": metal in the CT (", metal.components, " piece(s), ",
                       mm(metal.volume_mm3), " mm3 at or above ", metal.threshold_hu,
                       " HU, the largest at LPS (", mm(metal.centre_lps[0]), ", ", mm(metal.centre_lps[1]), ", ",
                       mm(metal.centre_lps[2]), ") mm): its streaks were removed from the ", slices,
                       " slices through it (S ", mm(metal.z_min_mm), " .. ", mm(metal.z_max_mm),
                       " mm, bridged from the slices on either side), and the ", cells.count,
                       " cells whose skin lies there (z ", mm(cells.z_min_mm), " .. ",
                       mm(cells.z_max_mm), " mm) are marked not valid (truncated): a plan there is "
                       "refused; model.json segmentation.metal"));
  }
  if (m.stats.valid_cells < m.stats.cells / 20)
    warn(reporter, cat(v.source, ": only ", m.stats.valid_cells, " of ", m.stats.cells,
             " cells have a valid thickness; check the thresholds and the bone segmentation"));
  return m;
}

MetalCells metal_cells(const CylindricalMaps& maps) {
  MetalCells out;
  const auto& g = maps.grid;
  if (maps.metal.size() != g.size()) return out;
  out.z_min_mm = std::numeric_limits<double>::infinity();
  out.z_max_mm = -out.z_min_mm;
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j)
      if (maps.metal[g.index(j, k)]) {
        ++out.count;
        out.z_min_mm = std::min(out.z_min_mm, g.z_mm(k));
        out.z_max_mm = std::max(out.z_max_mm, g.z_mm(k));
        out.row_first = out.count == 1 ? k : std::min(out.row_first, k);
        out.row_last = std::max(out.row_last, k);
      }
  if (out.count == 0) out.z_min_mm = out.z_max_mm = 0;
  return out;
}

namespace {

// model.json's segmentation.metal: whether metal was looked for and found, where, and which
// cells it made not valid.
json metal_json(const VolumeModel& m) {
  const MetalRegion& metal = m.metal;
  if (!metal.checked)
    return {{"checked", false},
            {"reason", m.modality == Modality::CT ? "not requested"
                                                  : "metal is found by its CT number (CT only)"}};
  json j = {{"checked", true}, {"found", metal.found}, {"threshold_hu", metal.threshold_hu}};
  if (!metal.found) return j;
  const MetalCells cells = metal_cells(m.maps);
  json slabs = json::array();
  for (const auto& [first, last] : metal.slabs) slabs.push_back({first, last});
  j["pieces"] = metal.components;
  j["voxels"] = metal.voxels;
  j["volume_mm3"] = metal.volume_mm3;
  j["max_hu"] = metal.max_hu;
  j["centre_lps_mm"] = detail::vec_json(metal.centre_lps);
  j["slice_axis"] = metal.slice_axis;
  j["slices"] = slabs;
  j["s_range_mm"] = {metal.z_min_mm, metal.z_max_mm};
  j["repair"] = "the slices holding metal and 1.5 mm (at least one slice) on either side are "
                "replaced by the linear interpolation between the clean slices around them, "
                "before segmenting; see docs/volume.md, \"Metal\"";
  j["cells"] = {{"count", cells.count},
                {"flag", "truncated"},
                {"rows", {cells.row_first, cells.row_last}},
                {"z_mm", {cells.z_min_mm, cells.z_max_mm}},
                {"rule", "cells whose column (base - 1 mm to skin + 2 mm) crosses a repaired "
                         "slice: skin and thickness not measured, filled"}};
  return j;
}

}  // namespace

void write_model(const VolumeModel& m, const fs::path& dir, bool force, Reporter* reporter) {
  const auto& seg = m.segmentation;
  ModelProvenance c;
  c.name = fs::path(m.source).filename().string();
  json source = {{"kind", "volume"},
                 {"path", m.source},
                 {"format", m.source_format},
                 {"modality", to_string(m.modality)},
                 {"dims", detail::vec_json(m.source_dims)},
                 {"spacing_mm", detail::vec_json(m.source_spacing_mm)},
                 {"notes", m.notes}};
  if (!m.chart_json.empty()) source["chart"] = json::parse(m.chart_json);
  if (!m.pose_json.empty()) source["pose"] = json::parse(m.pose_json);
  c.source_json = source.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  c.segmentation_json = json{{"skin_method", seg.skin_method},
                             {"skin_threshold", seg.skin_threshold},
                             {"bone_method", seg.bone_method},
                             {"bone_threshold", std::isfinite(seg.bone_threshold)
                                                    ? json(seg.bone_threshold) : json(nullptr)},
                             {"bone_is_approximate", seg.bone_is_approximate},
                             {"working_spacing_mm",
                              detail::vec_json(seg.working.geom.spacing_mm)},
                             {"head_volume_ml", seg.head_volume_ml},
                             {"bone_volume_ml", seg.bone_volume_ml},
                             {"detached_pieces", seg.detached_pieces},
                             {"detached_volume_ml", seg.detached_volume_ml},
                             {"metal", metal_json(m)}}
                            .dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  c.thickness_json = json{{"kind", seg.bone_is_approximate ? "approximate" : "measured"},
                          {"radial", "r_skin - r_bone along the ray from the axis"},
                          {"normal", "distance from the skin point to the nearest bone"},
                          {"fill", "invalid cells: r_skin and thickness filled by harmonic "
                                   "interpolation from valid cells; see validity.nrrd"},
                          {"base", base_json(m)},
                          {"layers", layers_json(m)}}
                         .dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  write_model_directory(m, c, dir, force, reporter);
}

}  // namespace caps

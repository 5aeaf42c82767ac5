#include "caps/volume/model.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <numeric>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/reporter.hpp"
#include "caps/core/units.hpp"
#include "caps/volume/image_io.hpp"
#include "caps/volume/isosurface.hpp"
#include "caps/volume/mesh_io.hpp"

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

json vec(const Eigen::Vector3d& v) { return json::array({v[0], v[1], v[2]}); }
json vec(const Eigen::Vector3i& v) { return json::array({v[0], v[1], v[2]}); }

double finite_or_null_guard(double x) { return std::isfinite(x) ? x : 0.0; }

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
    if (maps.measured_skin[i]) rs.push_back(maps.r_skin[i]);
    if (f != 0) continue;
    ++s.valid_cells;
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
      if (std::abs(th) <= 15 && maps.flags[g.index(j, k)] == 0)
        forehead.push_back(maps.thickness[g.index(j, k)]);
    }
  }
  s.forehead_thickness_mm = percentile(forehead, 0.5);
  return s;
}

VolumeModel build_volume_model(const Volume& v, const ModelOptions& o, Reporter* reporter) {
  VolumeModel m;
  m.source = v.source;
  m.source_format = v.format;
  m.modality = v.modality;
  m.source_dims = v.geom.dims;
  m.source_spacing_mm = v.geom.spacing_mm;
  m.notes = v.notes;
  m.segmentation = segment_head(v, o.segment, reporter);
  const CylinderAxis axis = o.axis ? *o.axis : fit_axis(m.segmentation);
  m.maps = cylindrical_maps(v, m.segmentation, axis, o.maps, reporter);
  m.stats = model_statistics(m.maps);
  {
    Progress progress(reporter, "extracting skin and bone surfaces", 2);
    const auto& seg = m.segmentation;
    m.skin = surface_of(seg.working, seg.skin, seg.skin_threshold, true, o);
    progress.update(1);
    const bool bone_by_threshold = std::isfinite(seg.bone_threshold);
    m.bone = surface_of(seg.working, seg.bone, bone_by_threshold ? seg.bone_threshold : 0.5,
                        bone_by_threshold, o);
  }
  for (const auto& n : m.segmentation.notes) m.notes.push_back(n);
  if (m.stats.valid_cells < m.stats.cells / 20)
    warn(reporter, cat(v.source, ": only ", m.stats.valid_cells, " of ", m.stats.cells,
             " cells have a valid thickness; check the thresholds and the bone segmentation"));
  return m;
}

void write_model(const VolumeModel& m, const fs::path& dir, bool force, Reporter* reporter) {
  const auto& seg = m.segmentation;
  ModelDirectoryContents c;
  c.maps = &m.maps;
  c.stats = &m.stats;
  c.skin = &m.skin;
  c.bone = &m.bone;
  c.name = fs::path(m.source).filename().string();
  c.source_json = json{{"kind", "volume"},
                       {"path", m.source},
                       {"format", m.source_format},
                       {"modality", to_string(m.modality)},
                       {"dims", vec(m.source_dims)},
                       {"spacing_mm", vec(m.source_spacing_mm)},
                       {"notes", m.notes}}
                      .dump();
  c.segmentation_json = json{{"skin_method", seg.skin_method},
                             {"skin_threshold", seg.skin_threshold},
                             {"bone_method", seg.bone_method},
                             {"bone_threshold", std::isfinite(seg.bone_threshold)
                                                    ? json(seg.bone_threshold) : json(nullptr)},
                             {"bone_is_approximate", seg.bone_is_approximate},
                             {"working_spacing_mm", vec(seg.working.geom.spacing_mm)},
                             {"head_volume_ml", seg.head_volume_ml},
                             {"bone_volume_ml", seg.bone_volume_ml},
                             {"detached_pieces", seg.detached_pieces},
                             {"detached_volume_ml", seg.detached_volume_ml}}
                            .dump();
  c.thickness_json = json{{"kind", seg.bone_is_approximate ? "approximate" : "measured"},
                          {"radial", "r_skin - r_bone along the ray from the axis"},
                          {"normal", "distance from the skin point to the nearest bone"},
                          {"fill", "invalid cells: r_skin and thickness filled by harmonic "
                                   "interpolation from valid cells; see validity.nrrd"}}
                         .dump();
  write_model_directory(c, dir, force, reporter);
}

void write_model_directory(const ModelDirectoryContents& c, const fs::path& dir, bool force,
                           Reporter* reporter) {
  if (!c.maps || !c.stats || !c.skin || !c.bone)
    throw InvalidInput("write_model_directory: maps, statistics, skin and bone are required");
  const auto& maps = *c.maps;
  const auto& g = maps.grid;
  if (c.color && (c.color->width != g.n_theta || c.color->height != g.n_z ||
                  c.color->rgb.size() != g.size() * 3))
    throw InvalidInput(cat("write_model_directory: the colour image is ", c.color->width, " x ",
                           c.color->height, ", expected the grid's ", g.n_theta, " x ", g.n_z));
  auto parse = [](const std::string& text, const char* what) {
    try {
      return text.empty() ? json::object() : json::parse(text);
    } catch (const json::exception& e) {
      throw InvalidInput(cat("write_model_directory: ", what, " is not valid JSON (", e.what(), ")"));
    }
  };
  OutputDirectory out(dir, force);
  const fs::path p = out.path();
  Progress progress(reporter, "writing the model", 8);
  write_map_nrrd(p / "r_skin.nrrd", maps.r_skin, g, "r_skin: skin radius", "mm");
  write_map_nrrd(p / "r_bone.nrrd", maps.r_bone, g, "r_bone: bone radius", "mm");
  write_map_nrrd(p / "thickness.nrrd", maps.thickness, g, "thickness: radial soft tissue", "mm");
  write_map_nrrd(p / "thickness_normal.nrrd", maps.thickness_normal, g,
                 "thickness_normal: skin to nearest bone", "mm");
  std::vector<float> flags(maps.flags.begin(), maps.flags.end());
  write_map_nrrd(p / "validity.nrrd", flags, g,
                 "validity: 0 valid; bit flags 1 no_skin, 2 no_bone, 4 undercut, 8 grazing, "
                 "16 truncated", "flags");
  progress.update(3);
  write_thickness_png(p / "thickness.png", maps, maps.thickness,
                      cat("Soft-tissue thickness (radial), ", c.name), c.credit);
  write_skin_png(p / "skin.png", maps, cat("Skin range image (shaded), ", c.name), c.credit);
  if (c.color) write_png(p / "color.png", *c.color);
  progress.update(5);
  write_ply(*c.skin, p / "skin.ply");
  write_ply(*c.bone, p / "bone.ply");
  progress.update(7);

  const auto& s = *c.stats;
  json j;
  j["format"] = "caps-model";
  j["format_version"] = kModelFormatVersion;
  j["created_by"] = "caps 0.1.0";
  j["units"] = {{"length", "mm"}, {"angle", "deg"}};
  j["frame"] = "LPS";
  j["source"] = parse(c.source_json, "source_json");
  j["axis"] = {{"origin_lps", vec(maps.axis.origin_lps)},
               {"direction", vec(maps.axis.direction)},
               {"front", vec(maps.axis.front)},
               {"left", vec(maps.axis.left())},
               {"convention", "theta = 0 at front, increasing towards the patient's left; "
                              "z along direction from origin_lps; r from the axis"}};
  j["grid"] = {{"n_theta", g.n_theta}, {"n_z", g.n_z},       {"theta0_deg", g.theta0_deg},
               {"dtheta_deg", g.dtheta_deg()}, {"z0_mm", g.z0_mm}, {"dz_mm", g.dz_mm},
               {"layout", "theta fastest; sample (j, k) at theta0 + j dtheta, z0 + k dz"}};
  j["segmentation"] = parse(c.segmentation_json, "segmentation_json");
  j["thickness"] = parse(c.thickness_json, "thickness_json");
  j["statistics"] = {
      {"cells", s.cells},
      {"valid_cells", s.valid_cells},
      {"valid_fraction", s.cells ? double(s.valid_cells) / s.cells : 0.0},
      {"flagged_cells", {{"no_skin", s.no_skin}, {"no_bone", s.no_bone}, {"undercut", s.undercut},
                         {"grazing", s.grazing}, {"truncated", s.truncated}}},
      {"thickness_mm", {{"mean", s.thickness_mean_mm}, {"median", s.thickness_median_mm},
                        {"p5", s.thickness_p5_mm}, {"p95", s.thickness_p95_mm}}},
      {"thickness_normal_median_mm", s.thickness_normal_median_mm},
      {"forehead_thickness_mm", finite_or_null_guard(s.forehead_thickness_mm)},
      {"face", {{"theta_deg", s.face_theta_deg}, {"z_mm", s.face_z_mm}}},
      {"r_skin_median_mm", s.r_skin_median_mm}};
  j["files"] = {{"r_skin", "r_skin.nrrd"},       {"r_bone", "r_bone.nrrd"},
                {"thickness", "thickness.nrrd"}, {"thickness_normal", "thickness_normal.nrrd"},
                {"validity", "validity.nrrd"},   {"thickness_png", "thickness.png"},
                {"skin_png", "skin.png"},        {"skin_mesh", "skin.ply"},
                {"bone_mesh", "bone.ply"}};
  if (c.color) j["files"]["color"] = "color.png";
  j["meshes"] = {
      {"skin", {{"vertices", c.skin->n_vertices()}, {"faces", c.skin->n_faces()},
                {"area_mm2", mesh_area(*c.skin)}, {"closed", is_closed_manifold(*c.skin)}}},
      {"bone", {{"vertices", c.bone->n_vertices()}, {"faces", c.bone->n_faces()},
                {"area_mm2", mesh_area(*c.bone)}, {"closed", is_closed_manifold(*c.bone)}}}};
  j["warnings"] = reporter ? reporter->warnings() : std::vector<std::string>{};
  write_text_atomic(p / "model.json", j.dump(2) + "\n");
  out.commit();
}

std::string read_model_json(const fs::path& dir) {
  const fs::path file = dir / "model.json";
  if (!fs::is_directory(dir))
    throw IoError(cat(dir.string(), ": not a model directory (no such folder); build one with "
                      "`caps model from-volume`"));
  std::ifstream in(file);
  if (!in) throw IoError(cat(file.string(), ": missing; is ", dir.string(), " a caps model?"));
  json j;
  try {
    in >> j;
  } catch (const json::exception& e) {
    throw InvalidInput(cat(file.string(), ": not valid JSON (", e.what(), ")"));
  }
  if (j.value("format", "") != "caps-model")
    throw InvalidInput(cat(file.string(), ": 'format' is not \"caps-model\""));
  const int version = j.value("format_version", -1);
  if (version != kModelFormatVersion)
    throw InvalidInput(cat(file.string(), ": format_version ", version, " is not supported (this "
                           "caps reads version ", kModelFormatVersion, "); rebuild the model"));
  if (j.contains("files"))
    for (const auto& [key, name] : j["files"].items())
      if (!fs::exists(dir / name.get<std::string>()))
        throw InvalidInput(cat(dir.string(), ": model.json names ", key, " = ",
                               name.get<std::string>(), " but the file is missing"));
  return j.dump(2);
}

std::string model_summary(const fs::path& dir) {
  const json j = json::parse(read_model_json(dir));
  const auto& s = j["statistics"];
  const auto& g = j["grid"];
  std::ostringstream os;
  os.precision(3);
  os << "model      " << dir.string() << " (format " << j["format_version"] << ")\n"
     << "source     " << j["source"]["path"].get<std::string>() << " ("
     << j["source"]["format"].get<std::string>() << ", "
     << j["source"]["modality"].get<std::string>() << ")\n"
     << "grid       " << g["n_theta"] << " x " << g["n_z"] << " (theta x z), dz "
     << g["dz_mm"].get<double>() << " mm, z " << g["z0_mm"].get<double>() << " .. "
     << g["z0_mm"].get<double>() + (g["n_z"].get<int>() - 1) * g["dz_mm"].get<double>()
     << " mm\n"
     << "skin       " << j["segmentation"]["skin_method"].get<std::string>() << "\n"
     << "bone       " << j["segmentation"]["bone_method"].get<std::string>() << "\n"
     << "valid      " << 100.0 * s["valid_fraction"].get<double>() << " % of cells\n"
     << "thickness  median " << s["thickness_mm"]["median"].get<double>() << " mm (5-95%: "
     << s["thickness_mm"]["p5"].get<double>() << " - " << s["thickness_mm"]["p95"].get<double>()
     << " mm), forehead " << s["forehead_thickness_mm"].get<double>() << " mm\n"
     << "face       theta " << s["face"]["theta_deg"].get<double>() << " deg, z "
     << s["face"]["z_mm"].get<double>() << " mm\n";
  return os.str();
}

}  // namespace caps

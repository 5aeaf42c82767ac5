#include "caps/app/slicer.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/fem/result_io.hpp"
#include "caps/plan/plan.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/render/drawn_skin.hpp"
#include "caps/render/overlay.hpp"
#include "caps/render/skin_surface.hpp"
#include "caps/surface/feature_lines.hpp"
#include "caps/surface/landmarks.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/volume/mesh_io.hpp"
#include "caps/volume/model_dir.hpp"
#include "caps/volume/read_volume.hpp"
#include "caps/volume/segment.hpp"
#include "json_fields.hpp"
#include "output_check.hpp"

CAPS_APP_REQUEST_JSON(caps::app::ExportSlicerRequest)
CAPS_APP_RESULT_JSON(caps::app::ExportSlicerResult)

namespace caps::app {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// ---- NRRD ---------------------------------------------------------------------------------

// The header lines every NRRD of the export shares: the grid in patient LPS (a column of `space
// directions` is voxel axis a's direction times its spacing; `space origin` the centre of voxel
// (0, 0, 0)), as caps's VolumeGeometry holds it.
std::string nrrd_geometry(const VolumeGeometry& g) {
  std::ostringstream h;
  h << std::setprecision(17);
  h << "dimension: 3\n"
    << "space: left-posterior-superior\n"
    << "sizes: " << g.dims[0] << " " << g.dims[1] << " " << g.dims[2] << "\n"
    << "space directions:";
  for (int a = 0; a < 3; ++a) {
    const Eigen::Vector3d d = g.direction.col(a) * g.spacing_mm[a];
    h << " (" << d[0] << "," << d[1] << "," << d[2] << ")";
  }
  h << "\nkinds: domain domain domain\n"
    << "endian: little\n"
    << "encoding: gzip\n"
    << "space origin: (" << g.origin_lps[0] << "," << g.origin_lps[1] << "," << g.origin_lps[2]
    << ")\n";
  return h.str();
}

// Writes an attached-header NRRD: `header` (ending in a newline), the blank line, then `bytes`
// gzip-compressed.
void write_nrrd(const fs::path& path, const std::string& header, const void* bytes,
                std::size_t n_bytes) {
  write_file_atomic(path, [&](const fs::path& tmp) {
    {
      std::ofstream out(tmp, std::ios::binary);
      out << header << "\n";
      if (!out) throw IoError(cat(path.string(), ": cannot write"));
    }
    gzFile f = gzopen(tmp.c_str(), "ab6");
    if (!f) throw IoError(cat(path.string(), ": cannot write"));
    const auto* p = static_cast<const char*>(bytes);
    std::size_t left = n_bytes;
    while (left > 0) {
      const unsigned chunk = static_cast<unsigned>(std::min<std::size_t>(left, 1u << 26));
      if (gzwrite(f, p, chunk) != static_cast<int>(chunk)) {
        gzclose(f);
        throw IoError(cat(path.string(), ": cannot write (disk full?)"));
      }
      p += chunk;
      left -= chunk;
    }
    if (gzclose(f) != Z_OK) throw IoError(cat(path.string(), ": cannot write"));
  });
}

// The volume as NRRD: 16-bit signed when every value is a whole number in range (a CT in HU),
// else 32-bit float.
void write_volume_nrrd(const fs::path& path, const Volume& v) {
  bool whole = true;
  for (const float x : v.data)
    if (!(x == std::nearbyint(x) && x >= -32768.0f && x <= 32767.0f)) {
      whole = false;
      break;
    }
  std::ostringstream h;
  h << "NRRD0004\n"
    << "# " << to_string(v.modality) << " volume the caps model was built from (" << v.format
    << ": " << v.source << ")\n"
    << "# frame: patient LPS, mm (caps's frame: volume/volume.hpp)\n"
    << "type: " << (whole ? "short" : "float") << "\n"
    << nrrd_geometry(v.geom) << "space units: \"mm\" \"mm\" \"mm\"\n";
  if (whole) {
    std::vector<std::int16_t> s(v.data.size());
    for (std::size_t i = 0; i < s.size(); ++i) s[i] = static_cast<std::int16_t>(v.data[i]);
    write_nrrd(path, h.str(), s.data(), s.size() * sizeof(std::int16_t));
  } else {
    write_nrrd(path, h.str(), v.data.data(), v.data.size() * sizeof(float));
  }
}

struct SegmentDef {
  std::string id, name;
  std::uint8_t label;
  Eigen::Vector3d color;
};

// ---- legacy VTK polydata -----------------------------------------------------------------

void put_be32(std::string& out, std::uint32_t x) {
  for (int s = 24; s >= 0; s -= 8) out.push_back(static_cast<char>((x >> s) & 0xff));
}
void put_float(std::string& out, double v) {
  const float f = static_cast<float>(v);
  std::uint32_t x;
  std::memcpy(&x, &f, sizeof x);
  put_be32(out, x);
}

struct PointArray {
  std::string name;
  Eigen::MatrixXd values;  ///< #V × 1 or #V × 3
};

// A legacy VTK (4.2, binary, big-endian as the format requires) polydata of triangles. Slicer
// reads the coordinate system from the title line ("SPACE=LPS"). The first 1-component array is
// the active SCALARS, the first 3-component one VECTORS, the others a FIELD.
void write_vtk(const fs::path& path, const TriMesh& mesh, const std::string& title,
               const std::vector<PointArray>& arrays) {
  const Eigen::Index n = mesh.V.rows();
  std::string b;
  b += "# vtk DataFile Version 4.2\n";
  std::string t = title + " SPACE=LPS";
  std::replace(t.begin(), t.end(), '\n', ' ');
  b += t.substr(0, 255) + "\n";
  b += "BINARY\nDATASET POLYDATA\n";
  b += cat("POINTS ", n, " float\n");
  for (Eigen::Index i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) put_float(b, mesh.V(i, c));
  b += cat("\nPOLYGONS ", mesh.F.rows(), " ", mesh.F.rows() * 4, "\n");
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    put_be32(b, 3);
    for (int c = 0; c < 3; ++c) put_be32(b, static_cast<std::uint32_t>(mesh.F(f, c)));
  }
  b += cat("\nPOINT_DATA ", n, "\n");
  const PointArray* scalars = nullptr;
  const PointArray* vectors = nullptr;
  std::vector<const PointArray*> others;
  for (const PointArray& a : arrays) {
    if (a.values.rows() != n) throw InvalidInput(cat(a.name, ": not one value per point"));
    if (a.values.cols() == 1 && !scalars)
      scalars = &a;
    else if (a.values.cols() == 3 && !vectors)
      vectors = &a;
    else
      others.push_back(&a);
  }
  auto put_values = [&](const PointArray& a) {
    for (Eigen::Index i = 0; i < n; ++i)
      for (Eigen::Index c = 0; c < a.values.cols(); ++c) put_float(b, a.values(i, c));
    b += "\n";
  };
  if (scalars) {
    b += cat("SCALARS ", scalars->name, " float 1\nLOOKUP_TABLE default\n");
    put_values(*scalars);
  }
  if (vectors) {
    b += cat("VECTORS ", vectors->name, " float\n");
    put_values(*vectors);
  }
  if (!others.empty()) {
    b += cat("FIELD FieldData ", others.size(), "\n");
    for (const PointArray* a : others) {
      b += cat(a->name, " ", a->values.cols(), " ", n, " float\n");
      put_values(*a);
    }
  }
  write_file_atomic(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out.write(b.data(), static_cast<std::streamsize>(b.size()));
    if (!out) throw IoError(cat(path.string(), ": cannot write"));
  });
}

// ---- markups --------------------------------------------------------------------------------

constexpr char kMarkupsSchema[] =
    "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/Resources/"
    "Schema/markups-schema-v1.0.3.json#";

struct MarkupPoint {
  std::string label, description;
  Eigen::Vector3d lps;
};

// One markup (a "Fiducial" point list or an open "Curve") in Slicer's markups JSON (schema
// v1.0.3): positions in LPS millimetres, locked (they are measurements, not handles).
json markup(const std::string& type, const std::string& name, const std::vector<MarkupPoint>& pts) {
  json cps = json::array();
  int id = 0;
  for (const MarkupPoint& p : pts) {
    cps.push_back({{"id", std::to_string(++id)},
                   {"label", p.label},
                   {"description", p.description},
                   {"associatedNodeID", ""},
                   {"position", {p.lps[0], p.lps[1], p.lps[2]}},
                   {"selected", true},
                   {"locked", true},
                   {"visibility", true},
                   {"positionStatus", "defined"}});
  }
  return {{"type", type},
          {"name", name},
          {"coordinateSystem", "LPS"},
          {"coordinateUnits", "mm"},
          {"locked", true},
          {"labelFormat", "%N-%d"},
          {"lastUsedControlPointNumber", id},
          {"controlPoints", cps},
          {"measurements", json::array()}};
}

void write_markups(const fs::path& path, const json& one_markup) {
  const json doc = {{"@schema", kMarkupsSchema}, {"markups", json::array({one_markup})}};
  write_text_atomic(path, doc.dump(2) + "\n");
}

// A file name from a feature line's or landmark's name ("upper_lip_vermilion").
std::string safe_name(const std::string& s) {
  std::string out;
  for (const char c : s) out += (std::isalnum(static_cast<unsigned char>(c)) || c == '_') ? c : '_';
  return out.empty() ? "line" : out;
}

// ---- the source volume -------------------------------------------------------------------

// The volume the model was built from, or nothing (with the reason as a warning).
std::optional<Volume> source_volume(const std::string& model_dir, const json& source,
                                    std::vector<std::string>& warnings) {
  if (source.value("kind", "volume") != "volume") {
    warnings.push_back(
        "the model was built from a surface scan: there is no CT or MR to write, "
        "and no segmentation");
    return std::nullopt;
  }
  // The path as model.json records it: as given to from-volume, so a relative one is relative to
  // where that ran, usually the folder that holds the model (`caps model from-volume ct.nii.gz -o
  // m`); tried as it is, then beside the model.
  const std::string recorded = source.value("path", "");
  std::string path;
  if (!recorded.empty()) {
    std::vector<fs::path> candidates = {recorded};
    if (fs::path(recorded).is_relative()) {
      const fs::path dir = fs::absolute(model_dir).lexically_normal();
      candidates.push_back(dir.parent_path() / recorded);
      candidates.push_back(dir / recorded);
    }
    for (const fs::path& c : candidates)
      if (fs::exists(c)) {
        path = c.string();
        break;
      }
  }
  if (path.empty()) {
    warnings.push_back(cat("the volume the model was built from (",
                           recorded.empty() ? "?" : recorded,
                           ") is not there: no CT/MR and no segmentation written; put it back "
                           "and export again to have them"));
    return std::nullopt;
  }
  Volume v = read_volume(path);
  if (source.contains("dims") && source.at("dims").is_array() && source.at("dims").size() == 3) {
    const auto& d = source.at("dims");
    bool same_spacing = true;
    if (source.contains("spacing_mm") && source.at("spacing_mm").is_array() &&
        source.at("spacing_mm").size() == 3)
      for (int a = 0; a < 3; ++a)
        same_spacing = same_spacing &&
                       std::abs(source.at("spacing_mm")[a].get<double>() - v.geom.spacing_mm[a]) <=
                           1e-4 * v.geom.spacing_mm[a];
    if (d[0] != v.geom.dims[0] || d[1] != v.geom.dims[1] || d[2] != v.geom.dims[2] ||
        !same_spacing) {
      warnings.push_back(cat("the volume at ", path, " has ", v.geom.dims[0], "x", v.geom.dims[1],
                             "x", v.geom.dims[2], " voxels of ", v.geom.spacing_mm[0], "x",
                             v.geom.spacing_mm[1], "x", v.geom.spacing_mm[2],
                             " mm, not the grid model.json records: it is not the volume the "
                             "model was built from; no CT/MR and no segmentation written"));
      return std::nullopt;
    }
  }
  const std::string modality = source.value("modality", "");
  if (modality == "CT") v.modality = Modality::CT;
  if (modality == "MR") v.modality = Modality::MR;
  return v;
}

// ---- the segmentation ----------------------------------------------------------------------

// The labelmap on the volume's grid: between the skin and the soft tissue's base along the
// model's radial ray at a voxel's (theta, z) (valid cells only: measured skin and base), dermis,
// fat and deep tissue split at the model's measured layer depths along that ray (without layers:
// one soft-tissue label), so that the segmentation agrees with the thickness the surfaces carry;
// elsewhere bone where segment_head()'s bone mask is (its working grid, nearest voxel: coarser
// than the model's sub-voxel base, which is why the soft tissue is labelled first). 0 elsewhere.
std::vector<std::uint8_t> tissue_labels(const Volume& v, const Segmentation& seg,
                                        const PatientModel& model, bool layers, bool bone) {
  const VolumeGeometry& g = v.geom;
  const CylindricalMaps& maps = model.maps();
  const CylinderGrid& grid = maps.grid;
  std::vector<std::uint8_t> labels(g.n_voxels(), 0);
  const VolumeGeometry& bg = seg.bone.geom;
  const Eigen::Matrix3d to_bone = (bg.direction * bg.spacing_mm.asDiagonal()).inverse();
  const double r_max = *std::max_element(maps.r_skin.begin(), maps.r_skin.end()) + 1.0;
  // The soft tissue's label at p: 1..3 (or 1 without layers) between the skin and the base along
  // the model's ray, else 0.
  auto soft_tissue_label = [&](const Eigen::Vector3d& p) -> std::uint8_t {
    const CylindricalPoint c = model.to_cylindrical(p);
    if (c.r_mm > r_max || !model.has_z(c.z_mm)) return 0;
    // the nearest cell must be valid (measured skin and base)
    int jj = static_cast<int>(std::lround((c.theta_deg - grid.theta0_deg) / grid.dtheta_deg()));
    jj = ((jj % grid.n_theta) + grid.n_theta) % grid.n_theta;
    const int kk = std::clamp(static_cast<int>(std::lround((c.z_mm - grid.z0_mm) / grid.dz_mm)), 0,
                              grid.n_z - 1);
    if (!maps.is_valid(jj, kk)) return 0;
    const double depth = model.r_skin(c.theta_deg, c.z_mm) - c.r_mm;
    const double t = model.thickness(c.theta_deg, c.z_mm);
    if (depth < 0 || depth > t) return 0;
    if (!layers) return 1;
    const double ts = model.thickness_skin(c.theta_deg, c.z_mm);
    const double tf = model.thickness_fat(c.theta_deg, c.z_mm);
    return depth < ts ? 1 : depth < ts + tf ? 2 : 3;
  };
  // Slices in parallel (each voxel is labelled on its own; the model's samplers are const).
  tbb::parallel_for(tbb::blocked_range<int>(0, g.dims[2]), [&](const tbb::blocked_range<int>& ks) {
    for (int k = ks.begin(); k < ks.end(); ++k)
      for (int j = 0; j < g.dims[1]; ++j)
        for (int i = 0; i < g.dims[0]; ++i) {
          const Eigen::Vector3d p = g.index_to_lps(Eigen::Vector3d(i, j, k));
          const std::size_t at = g.linear(i, j, k);
          labels[at] = soft_tissue_label(p);
          if (labels[at] == 0 && bone) {
            const Eigen::Vector3d b = to_bone * (p - bg.origin_lps);
            const int bi = static_cast<int>(std::lround(b[0])),
                      bj = static_cast<int>(std::lround(b[1])),
                      bk = static_cast<int>(std::lround(b[2]));
            if (bg.contains(bi, bj, bk) && seg.bone.at(bi, bj, bk)) labels[at] = 4;
          }
        }
  });
  return labels;
}

// Slicer's segmentation file: one labelmap layer (3-D, unsigned char) on the volume's grid, with
// the Segment<N>_* and Segmentation_* key/value fields its storage node reads.
// Returns each segment's voxel count.
std::vector<long long> write_segmentation(const fs::path& path, const Volume& v,
                                          const std::vector<std::uint8_t>& labels,
                                          const std::vector<SegmentDef>& segments) {
  const VolumeGeometry& g = v.geom;
  std::ostringstream h;
  std::vector<long long> counts;
  h << "NRRD0004\n"
    << "# caps tissue segmentation on the grid of the volume the model was built from\n"
    << "# frame: patient LPS, mm (caps's frame: volume/volume.hpp)\n"
    << "type: unsigned char\n"
    << nrrd_geometry(g) << "space units: \"mm\" \"mm\" \"mm\"\n"
    << "Segmentation_MasterRepresentation:=Binary labelmap\n"
    << "Segmentation_ContainedRepresentationNames:=Binary labelmap|\n"
    << "Segmentation_ReferenceImageExtentOffset:=0 0 0\n";
  int index = 0;
  for (const SegmentDef& s : segments) {
    int lo[3] = {g.dims[0], g.dims[1], g.dims[2]}, hi[3] = {-1, -1, -1};
    long long n = 0;
    for (int k = 0; k < g.dims[2]; ++k)
      for (int j = 0; j < g.dims[1]; ++j)
        for (int i = 0; i < g.dims[0]; ++i)
          if (labels[g.linear(i, j, k)] == s.label) {
            ++n;
            const int ijk[3] = {i, j, k};
            for (int a = 0; a < 3; ++a) {
              lo[a] = std::min(lo[a], ijk[a]);
              hi[a] = std::max(hi[a], ijk[a]);
            }
          }
    const std::string key = cat("Segment", index++, "_");
    h << key << "ID:=" << s.id << "\n"
      << key << "Name:=" << s.name << "\n"
      << key << "NameAutoGenerated:=0\n"
      << key << "Color:=" << s.color[0] << " " << s.color[1] << " " << s.color[2] << "\n"
      << key << "ColorAutoGenerated:=0\n"
      << key << "LabelValue:=" << int(s.label) << "\n"
      << key << "Layer:=0\n";
    if (n > 0)
      h << key << "Extent:=" << lo[0] << " " << hi[0] << " " << lo[1] << " " << hi[1] << " "
        << lo[2] << " " << hi[2] << "\n";
    else
      h << key << "Extent:=0 -1 0 -1 0 -1\n";
    counts.push_back(n);
  }
  write_nrrd(path, h.str(), labels.data(), labels.size());
  return counts;
}

// ---- surfaces ------------------------------------------------------------------------------

// The model's soft-tissue thickness at each skin vertex's (theta, z) (bilinear, as `caps model
// site` samples it): along the normal (active scalars), along the radial ray, the layers along
// the normal where the model has them, and 1/0 whether every blended cell is valid (measured).
std::vector<PointArray> skin_arrays(const PatientModel& model, const TriMesh& skin) {
  const Eigen::Index n = skin.V.rows();
  const bool layers = model.has_layers();
  Eigen::VectorXd tn(n), tr(n), ok(n), ds(n), df(n), dd(n);
  const CylindricalMaps& m = model.maps();
  for (Eigen::Index i = 0; i < n; ++i) {
    const CylindricalPoint c = model.to_cylindrical(skin.V.row(i).transpose());
    tn[i] = model.thickness_normal(c.theta_deg, c.z_mm);
    tr[i] = model.thickness(c.theta_deg, c.z_mm);
    ok[i] = flags_valid(model.flags_at(c.theta_deg, c.z_mm)) ? 1.0 : 0.0;
    if (layers) {
      ds[i] = model.sample(m.thickness_skin_normal, c.theta_deg, c.z_mm);
      df[i] = model.sample(m.thickness_fat_normal, c.theta_deg, c.z_mm);
      dd[i] = model.sample(m.thickness_deep_normal, c.theta_deg, c.z_mm);
    }
  }
  std::vector<PointArray> a = {
      {"thickness_normal_mm", tn}, {"thickness_radial_mm", tr}, {"thickness_measured", ok}};
  if (layers) {
    a.push_back({"dermis_normal_mm", ds});
    a.push_back({"fat_normal_mm", df});
    a.push_back({"deep_normal_mm", dd});
  }
  return a;
}

// A bone vertex carries the thickness of the skin above it where it lies on the model's base
// (within kOnBaseMm of r_bone along its radial ray, in a valid cell); elsewhere (the inner table,
// the skull base, bone the rays do not reach) NaN.
constexpr double kOnBaseMm = 2.0;
std::vector<PointArray> bone_arrays(const PatientModel& model, const TriMesh& bone) {
  const Eigen::Index n = bone.V.rows();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Eigen::VectorXd tn(n), tr(n), on(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const CylindricalPoint c = model.to_cylindrical(bone.V.row(i).transpose());
    const bool base = model.has_z(c.z_mm) && flags_valid(model.flags_at(c.theta_deg, c.z_mm)) &&
                      std::abs(c.r_mm - model.r_bone(c.theta_deg, c.z_mm)) <= kOnBaseMm;
    on[i] = base ? 1.0 : 0.0;
    tn[i] = base ? model.thickness_normal(c.theta_deg, c.z_mm) : nan;
    tr[i] = base ? model.thickness(c.theta_deg, c.z_mm) : nan;
  }
  return {{"thickness_normal_mm", tn}, {"thickness_radial_mm", tr}, {"on_base", on}};
}

}  // namespace

ExportSlicerResult run_export_slicer(const ExportSlicerRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  // Every input is read and checked before anything is written.
  const ModelInfo info = read_model_info(r.model);
  const PatientModel model = PatientModel::load(r.model);
  const json mj = json::parse(read_model_json(r.model));
  std::optional<plan::Plan> plan;
  if (!r.plan.empty()) {
    plan = plan::read_plan(r.plan);
    if (!plan->model_hash.empty() && !info.content_hash.empty() &&
        plan->model_hash != info.content_hash)
      throw InvalidInput(cat("--plan ", r.plan, " was made on another model (its model hash ",
                             plan->model_hash, ", ", r.model, "'s is ", info.content_hash,
                             "): export the plan with the model it was made on"));
  }
  std::optional<fem::Mesh> fe_mesh;
  Eigen::MatrixX3d u;
  Eigen::VectorXd max_principal;
  if (!r.result.empty()) {
    // A folder of `caps simulate` (the mesh and its solution); the readers' errors name the file.
    const std::string what = cat("--result ", r.result, " (a folder of caps simulate): ");
    try {
      fe_mesh = fem::read_mesh_dir(r.result);
      u = fem::read_result_displacement(r.result, fe_mesh->n_nodes());
      max_principal = fem::read_result_max_principal(r.result, fe_mesh->n_nodes());
    } catch (const IoError& e) {
      throw IoError(what + e.what());
    } catch (const InvalidInput& e) {
      throw InvalidInput(what + e.what());
    }
  }

  ExportSlicerResult out;
  out.output = r.output;
  Progress progress(reporter, "exporting for 3D Slicer", 5);
  const json source = mj.value("source", json::object());
  std::optional<Volume> volume = source_volume(r.model, source, out.warnings);

  // The post-operative skin first: a result of another model is refused before any writing.
  std::optional<render::SkinSurfaces> post;
  std::optional<render::ScalarMap> tension;
  if (fe_mesh) {
    try {
      const int n = render::full_resolution_subdivisions(model, *fe_mesh);
      const render::DrawnSkin drawn = render::load_drawn_skin(model, r.model, reporter);
      post = render::displaced_skin(model, *fe_mesh, &u, n, &drawn);
      tension = render::tension_map(*post, *fe_mesh, max_principal);
    } catch (const InvalidInput& e) {
      throw InvalidInput(cat("--result ", r.result, " does not lie on the skin of ", r.model,
                             " (a simulation of another model?): ", e.what()));
    }
  }
  progress.update(1);

  OutputDirectory dir(r.output, r.force);
  const fs::path d = dir.path();
  json segments_json = json::array();
  if (volume) {
    const std::string name = volume->modality == Modality::CT   ? "ct"
                             : volume->modality == Modality::MR ? "mr"
                                                                : "volume";
    out.volume_file = name + ".nrrd";
    write_volume_nrrd(d / out.volume_file, *volume);
    out.files.push_back(out.volume_file);
    if (!volume->acquired.empty())
      out.warnings.push_back(cat(out.volume_file,
                                 ": the reader filled in voxels the scanner did "
                                 "not acquire (outside a tilted gantry's slab, resampled onto a "
                                 "regular grid): they hold the reader's fill value"));
    // The segmentation as the model was made: the recorded thresholds.
    SegmentOptions so;
    const json seg_json = mj.value("segmentation", json::object());
    if (seg_json.contains("skin_threshold") && seg_json.at("skin_threshold").is_number())
      so.skin_threshold = seg_json.at("skin_threshold").get<double>();
    if (seg_json.contains("bone_threshold") && seg_json.at("bone_threshold").is_number())
      so.bone_threshold = seg_json.at("bone_threshold").get<double>();
    const bool bone_from_mask = seg_json.value("bone_method", "").rfind("mask ", 0) == 0;
    const Segmentation seg = segment_head(*volume, so, reporter);
    const bool layers = model.has_layers();
    const bool bone = !bone_from_mask && !seg.bone_is_approximate;
    if (bone_from_mask)
      out.warnings.push_back(
          "the model's bone came from a separate mask (--bone-mask): the "
          "segmentation has no bone segment");
    if (seg.bone_is_approximate)
      out.warnings.push_back(cat("the volume shows no bone caps can threshold (", seg.bone_method,
                                 "): the segmentation has no bone segment"));
    if (!layers)
      out.warnings.push_back(
          "the model has no tissue layers (not a CT): the soft tissue is one "
          "segment");
    std::vector<SegmentDef> defs;
    if (layers) {
      defs.push_back({"dermis", "skin (dermis)", 1, {177 / 255.0, 122 / 255.0, 101 / 255.0}});
      defs.push_back({"fat", "subcutaneous fat", 2, {230 / 255.0, 220 / 255.0, 70 / 255.0}});
      defs.push_back({"deep", "deep tissue", 3, {192 / 255.0, 104 / 255.0, 88 / 255.0}});
    } else {
      defs.push_back({"soft_tissue", "soft tissue", 1, {177 / 255.0, 122 / 255.0, 101 / 255.0}});
    }
    if (bone) defs.push_back({"bone", "bone", 4, {241 / 255.0, 214 / 255.0, 145 / 255.0}});
    const std::vector<std::uint8_t> labels = tissue_labels(*volume, seg, model, layers, bone);
    const std::vector<long long> counts =
        write_segmentation(d / "tissue.seg.nrrd", *volume, labels, defs);
    out.files.push_back("tissue.seg.nrrd");
    for (std::size_t i = 0; i < defs.size(); ++i) {
      out.segments_text += cat(i ? ", " : "", defs[i].id, " ", counts[i]);
      segments_json.push_back({{"id", defs[i].id},
                               {"name", defs[i].name},
                               {"label", defs[i].label},
                               {"voxels", counts[i]}});
    }
  }
  progress.update(2);

  // Surfaces.
  const fs::path skin_ply = fs::path(r.model) / model_file::kSkinMesh;
  const fs::path bone_ply = fs::path(r.model) / model_file::kBoneMesh;
  if (fs::exists(skin_ply)) {
    const TriMesh skin = read_ply(skin_ply);
    write_vtk(d / "skin.vtk", skin, "caps skin surface (the model's skin.ply), patient LPS mm;",
              skin_arrays(model, skin));
    out.files.push_back("skin.vtk");
  }
  if (fs::exists(bone_ply)) {
    const TriMesh bone = read_ply(bone_ply);
    if (bone.V.rows() > 0) {
      write_vtk(d / "bone.vtk", bone, "caps bone surface (the model's bone.ply), patient LPS mm;",
                bone_arrays(model, bone));
      out.files.push_back("bone.vtk");
    }
  }
  progress.update(3);

  // Markups: the landmarks as recorded in model.json (found anew where it has none), the
  // feature lines, the plan's cutting paths.
  const Landmarks landmarks = info.landmarks_json.empty()
                                  ? find_landmarks(model)
                                  : landmarks_from_json(info.landmarks_json, r.model);
  std::vector<MarkupPoint> points;
  for (const Landmark& l : landmarks.items)
    if (l.found)
      points.push_back({l.name,
                        cat("caps landmark (docs/landmarks.md); soft tissue ",
                            std::round(l.thickness_mm * 10) / 10, " mm along the normal",
                            l.doubt.empty() ? std::string() : cat("; doubt: ", l.doubt)),
                        l.lps});
  if (!info.features_json.empty()) {
    const FeatureLines lines = feature_lines_from_json(info.features_json, r.model);
    fs::create_directories(d / "features");
    for (const FeatureLine& f : lines.items) {
      if (!f.found || f.lps.empty()) continue;
      if (f.lps.size() == 1 || f.along == "point") {
        points.push_back({f.name, "caps feature point (docs/landmarks.md)", f.lps.front()});
        continue;
      }
      std::vector<MarkupPoint> pts;
      for (std::size_t i = 0; i < f.lps.size(); ++i)
        pts.push_back({cat(f.name, "-", i + 1), "", f.lps[i]});
      const std::string file = cat("features/", safe_name(f.name), ".mrk.json");
      write_markups(d / file, markup("Curve", f.name, pts));
      out.files.push_back(file);
      ++out.curves;
    }
  }
  if (!points.empty()) {
    write_markups(d / "landmarks.mrk.json", markup("Fiducial", "landmarks", points));
    out.files.push_back("landmarks.mrk.json");
    out.landmarks = static_cast<int>(points.size());
  } else {
    out.warnings.push_back("no landmark was found on the model: no landmarks.mrk.json");
  }
  if (plan) {
    const auto lines = render::plan_lines(*plan, model);
    fs::create_directories(d / "plan");
    int i = 0;
    for (const auto& line : lines) {
      std::vector<MarkupPoint> pts;
      for (std::size_t p = 0; p < line.size(); ++p)
        pts.push_back({cat("cut", i + 1, "-", p + 1), "", line[p]});
      const std::string file = cat("plan/incision_", ++i, ".mrk.json");
      write_markups(d / file, markup("Curve", cat(plan->procedure, " incision ", i), pts));
      out.files.push_back(file);
      ++out.curves;
    }
    // An excision's wound border (the border loop with its offsets applied), a closed curve
    // sampled on the skin about every millimetre, across the seam the short way.
    if (!plan->excisions.empty()) {
      const plan::BorderLoop loop = plan::border_loop(*plan);
      std::vector<MarkupPoint> pts;
      for (int a = 0; a < loop.size(); ++a) {
        const Eigen::Vector2d p0 = loop.theta_z[a], p1 = loop.theta_z[(a + 1) % loop.size()];
        double dt = p1[0] - p0[0];
        dt -= 360.0 * std::round(dt / 360.0);
        const double len = (model.skin_point(p1[0], p1[1]) - model.skin_point(p0[0], p0[1])).norm();
        const int n = std::max(1, static_cast<int>(std::ceil(len / 1.0)));
        for (int k = 0; k < n; ++k) {
          const double t = static_cast<double>(k) / n;
          pts.push_back({cat("border-", pts.size() + 1), "",
                         model.skin_point(p0[0] + t * dt, p0[1] + t * (p1[1] - p0[1]))});
        }
      }
      write_markups(d / "plan/wound_border.mrk.json",
                    markup("ClosedCurve", cat(plan->procedure, " wound border"), pts));
      out.files.push_back("plan/wound_border.mrk.json");
      ++out.curves;
    }
  }
  progress.update(4);

  if (post) {
    const Eigen::MatrixX3d disp = post->post.V - post->pre.V;
    const Eigen::VectorXd mag = disp.rowwise().norm();
    Eigen::VectorXd on_mesh(post->post.V.rows());
    for (Eigen::Index i = 0; i < on_mesh.size(); ++i) on_mesh[i] = post->vertex_element[i] >= 0;
    write_vtk(d / "skin_postop.vtk", post->post,
              "caps post-operative skin (displaced_skin of the result), patient LPS mm; tension "
              "kPa, displacement mm;",
              {{"tension_kPa", tension->value},
               {"displacement_mm", disp},
               {"displacement_magnitude_mm", mag},
               {"on_fe_mesh", on_mesh}});
    out.files.push_back("skin_postop.vtk");
    out.max_displacement_mm = mag.size() ? mag.maxCoeff() : 0.0;
    out.max_tension_kpa = tension->value.size() ? tension->value.maxCoeff() : 0.0;
  }

  for (const std::string& w : out.warnings) warn(reporter, w);
  json s = json::parse(to_json(out));
  s["format"] = "caps-slicer-export";
  s["frame"] = "LPS";
  s["units"] = {{"length", "mm"}, {"tension", "kPa"}};
  s["model"] = r.model;
  s["model_hash"] = info.content_hash;
  s["segmentation"] = segments_json;
  write_text_atomic(d / "summary.json", s.dump(2) + "\n");
  dir.commit();
  progress.done();
  return out;
}

std::string summary(const ExportSlicerResult& r) {
  return cat("caps model export-slicer: ", r.files.size(), " files in ", r.output,
             r.volume_file.empty() ? " (no volume)"
                                   : cat(" (", r.volume_file, ", segments ", r.segments_text, ")"),
             ", ", r.landmarks, " landmark points, ", r.curves, " curves");
}

}  // namespace caps::app

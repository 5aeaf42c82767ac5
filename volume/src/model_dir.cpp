#include "caps/volume/model_dir.hpp"

#include <nlohmann/json.hpp>
#include <tbb/task_group.h>

#include <cmath>
#include <fstream>
#include <sstream>
#include <tuple>

#include "caps/core/atomic_output.hpp"
#include "caps/core/checked_numbers.hpp"
#include "caps/core/error.hpp"
#include "caps/core/file_access.hpp"
#include "caps/core/json_file.hpp"
#include "caps/core/reporter.hpp"
#include "caps/image/image_io.hpp"
#include "caps/volume/isosurface.hpp"
#include "caps/volume/map_nrrd.hpp"
#include "caps/volume/mesh_io.hpp"
#include "caps/volume/model_figures.hpp"
#include "json_vectors.hpp"

namespace fs = std::filesystem;
using nlohmann::json;

namespace caps {
namespace {

Eigen::Vector3d vec3(const json& v) {
  return {v.at(0).get<double>(), v.at(1).get<double>(), v.at(2).get<double>()};
}

double finite_or_zero(double x) { return std::isfinite(x) ? x : 0.0; }

json parse_object(const std::string& text, const char* what) {
  return text.empty() ? json::object() : parse_json<json>(text, cat("model.json: ", what));
}

// model.json's "files": every file the directory holds, by role.
json files_json(bool has_color, bool has_layers) {
  namespace f = model_file;
  json files = {{"r_skin", f::kRSkin},          {"r_bone", f::kRBone},
                {"thickness", f::kThickness},   {"thickness_normal", f::kThicknessNormal},
                {"validity", f::kValidity},     {"thickness_png", f::kThicknessPng},
                {"skin_png", f::kSkinPng},      {"skin_mesh", f::kSkinMesh},
                {"bone_mesh", f::kBoneMesh}};
  if (has_color) files["color"] = f::kColor;
  if (has_layers)
    files.update({{"thickness_skin", f::kThicknessSkin},
                  {"thickness_fat", f::kThicknessFat},
                  {"thickness_deep", f::kThicknessDeep},
                  {"thickness_skin_normal", f::kThicknessSkinNormal},
                  {"thickness_fat_normal", f::kThicknessFatNormal},
                  {"thickness_deep_normal", f::kThicknessDeepNormal},
                  {"layer_validity", f::kLayerValidity},
                  {"layer_validity_normal", f::kLayerValidityNormal},
                  {"layer_skin_png", f::kLayerSkinPng},
                  {"layer_fat_png", f::kLayerFatPng},
                  {"layer_deep_png", f::kLayerDeepPng}});
  return files;
}

json statistics_json(const ModelStatistics& s) {
  return {{"cells", s.cells},
          {"valid_cells", s.valid_cells},
          {"valid_fraction", s.cells ? double(s.valid_cells) / s.cells : 0.0},
          {"flagged_cells", {{"no_skin", s.no_skin}, {"no_bone", s.no_bone}, {"undercut", s.undercut},
                             {"grazing", s.grazing}, {"truncated", s.truncated},
                             {"base_cavity", s.base_cavity}, {"eye", s.eye},
                             {"base_tissue", s.base_tissue}}},
          {"thickness_mm", {{"mean", s.thickness_mean_mm}, {"median", s.thickness_median_mm},
                            {"p5", s.thickness_p5_mm}, {"p95", s.thickness_p95_mm}}},
          {"thickness_normal_median_mm", s.thickness_normal_median_mm},
          {"forehead_thickness_mm", finite_or_zero(s.forehead_thickness_mm)},
          {"face", {{"theta_deg", s.face_theta_deg}, {"z_mm", s.face_z_mm}}},
          {"r_skin_median_mm", s.r_skin_median_mm},
          {"layers", {{"cells", s.layer_cells}, {"no_fat", s.no_fat},
                      {"several_fat_bands", s.several_fat_bands},
                      {"median_mm", {{"skin", s.skin_layer_median_mm}, {"fat", s.fat_median_mm},
                                     {"deep", s.deep_median_mm}}}}}};
}

// A count in model.json: a whole number from 0 to 2^53 (a cast of 1e300 or -1 would be wrong or
// undefined); `where` names the file and the object.
std::int64_t count_field(const json& o, const char* key, const std::string& where) {
  const double x = o.value(key, 0.0);
  if (!is_whole_in(x, 0, 9007199254740992.0))
    throw InvalidInput(cat(where, ".", key, " = ", x, " is not a count; rebuild the model"));
  return static_cast<std::int64_t>(x);
}

// Missing statistics read as 0: they describe the model, nothing downstream depends on them.
ModelStatistics statistics_of(const json& j, const std::string& where) {
  ModelStatistics s;
  if (!j.is_object()) return s;
  auto count = [&](const json& o, const char* key) {
    return static_cast<std::size_t>(count_field(o, key, where));
  };
  auto num = [](const json& o, const char* key) { return o.value(key, 0.0); };
  const json none = json::object();
  auto child = [&none](const json& o, const char* key) -> const json& {
    return o.contains(key) ? o[key] : none;
  };
  const json& flagged = child(j, "flagged_cells");
  const json& t = child(j, "thickness_mm");
  const json& face = child(j, "face");
  s.cells = count(j, "cells");
  s.valid_cells = count(j, "valid_cells");
  s.no_skin = count(flagged, "no_skin");
  s.no_bone = count(flagged, "no_bone");
  s.undercut = count(flagged, "undercut");
  s.grazing = count(flagged, "grazing");
  s.truncated = count(flagged, "truncated");
  s.base_cavity = count(flagged, "base_cavity");
  s.base_tissue = count(flagged, "base_tissue");
  s.eye = count(flagged, "eye");
  s.thickness_mean_mm = num(t, "mean");
  s.thickness_median_mm = num(t, "median");
  s.thickness_p5_mm = num(t, "p5");
  s.thickness_p95_mm = num(t, "p95");
  s.thickness_normal_median_mm = num(j, "thickness_normal_median_mm");
  s.forehead_thickness_mm = num(j, "forehead_thickness_mm");
  s.face_theta_deg = num(face, "theta_deg");
  s.face_z_mm = num(face, "z_mm");
  s.r_skin_median_mm = num(j, "r_skin_median_mm");
  const json& layers = child(j, "layers");
  const json& medians = child(layers, "median_mm");
  s.layer_cells = count(layers, "cells");
  s.no_fat = count(layers, "no_fat");
  s.several_fat_bands = count(layers, "several_fat_bands");
  s.skin_layer_median_mm = num(medians, "skin");
  s.fat_median_mm = num(medians, "fat");
  s.deep_median_mm = num(medians, "deep");
  return s;
}

json mesh_json(const MeshSummary& m) {
  return {{"vertices", m.vertices}, {"faces", m.faces}, {"area_mm2", m.area_mm2}, {"closed", m.closed}};
}

MeshSummary mesh_summary_of(const json& j, const std::string& where) {
  MeshSummary m;
  if (!j.is_object()) return m;
  m.vertices = count_field(j, "vertices", where);
  m.faces = count_field(j, "faces", where);
  m.area_mm2 = j.value("area_mm2", 0.0);
  m.closed = j.value("closed", false);
  return m;
}

MeshSummary summary_of(const TriMesh& m) {
  return {m.n_vertices(), m.n_faces(), mesh_area(m), is_closed_manifold(m)};
}

json to_json(const ModelInfo& info) {
  const auto& a = info.axis;
  const auto& g = info.grid;
  json j;
  j["format"] = "caps-model";
  j["format_version"] = info.format_version;
  j["created_by"] = info.created_by;
  j["units"] = {{"length", "mm"}, {"angle", "deg"}};
  j["frame"] = "LPS";
  j["source"] = parse_object(info.source_json, "source");
  j["axis"] = {{"origin_lps", detail::vec_json(a.origin_lps)},
               {"direction", detail::vec_json(a.direction)},
               {"front", detail::vec_json(a.front)},
               {"left", detail::vec_json(a.left())},
               {"convention", "theta = 0 at front, increasing towards the patient's left; "
                              "z along direction from origin_lps; r from the axis"}};
  j["grid"] = {{"n_theta", g.n_theta}, {"n_z", g.n_z},       {"theta0_deg", g.theta0_deg},
               {"dtheta_deg", g.dtheta_deg()}, {"z0_mm", g.z0_mm}, {"dz_mm", g.dz_mm},
               {"layout", "theta fastest; sample (j, k) at theta0 + j dtheta, z0 + k dz"}};
  j["segmentation"] = parse_object(info.segmentation_json, "segmentation");
  j["thickness"] = parse_object(info.thickness_json, "thickness");
  j["statistics"] = statistics_json(info.stats);
  j["files"] = files_json(info.has_color, info.has_layers);
  j["meshes"] = {{"skin", mesh_json(info.skin)}, {"bone", mesh_json(info.bone)}};
  if (!info.content_hash.empty()) j["content_hash"] = info.content_hash;
  if (!info.landmarks_json.empty()) j["landmarks"] = parse_object(info.landmarks_json, "landmarks");
  if (!info.features_json.empty()) j["features"] = parse_object(info.features_json, "features");
  j["warnings"] = info.warnings;
  return j;
}

// model.json of `dir`, with the format, the version and the files it names checked.
json load_model_json(const fs::path& dir) {
  const fs::path file = dir / model_file::kJson;
  const std::string why = unreadable_reason(dir, true);
  if (!why.empty())
    throw IoError(cat(dir.string(), ": not a model directory (", why, "); build one with "
                      "`caps model from-volume`"));
  const json j = read_json_file<json>(file, cat("is ", dir.string(), " a caps model?"));
  // Checked by hand: json::value() and get() throw on a field of another type.
  if (!j.is_object() || !j.contains("format") || j["format"] != "caps-model")
    throw InvalidInput(cat(file.string(), ": 'format' is not \"caps-model\""));
  const json version = j.contains("format_version") ? j["format_version"] : json(-1);
  if (!version.is_number_integer() || version.get<long long>() != kModelFormatVersion)
    throw InvalidInput(cat(file.string(), ": format_version ", version.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace), " is not supported "
                           "(this caps reads version ", kModelFormatVersion, "); rebuild the model"));
  if (j.contains("files")) {
    if (!j["files"].is_object())
      throw InvalidInput(cat(file.string(), ": \"files\" must be an object of file names"));
    for (const auto& [key, name] : j["files"].items()) {
      if (!name.is_string())
        throw InvalidInput(cat(file.string(), ": files.", key, " = ", name.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace),
                               " is not a file name"));
      const std::string why = unreadable_reason(dir / name.get<std::string>());
      if (!why.empty())
        throw InvalidInput(cat(dir.string(), ": model.json names ", key, " = ",
                               name.get<std::string>(), " but that file cannot be read (", why,
                               ")"));
    }
  }
  return j;
}

}  // namespace

std::string ModelInfo::source_kind() const {
  return parse_object(source_json, "source").value("kind", std::string("volume"));
}

std::string ModelInfo::thickness_kind() const {
  return parse_object(thickness_json, "thickness").value("kind", std::string());
}

std::string model_json_text(const ModelInfo& info) { return to_json(info).dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n"; }

namespace {

ModelInfo read_model_info_fields(const fs::path& dir);

}  // namespace

ModelInfo read_model_info(const fs::path& dir) {
  try {
    return read_model_info_fields(dir);
  } catch (const json::exception& e) {
    throw InvalidInput(cat((dir / model_file::kJson).string(), ": a field is missing or of the "
                           "wrong type (", e.what(), "); rebuild the model"));
  }
}

namespace {

ModelInfo read_model_info_fields(const fs::path& dir) {
  const json j = load_model_json(dir);
  const fs::path file = dir / model_file::kJson;
  ModelInfo info;
  info.format_version = j.at("format_version").get<int>();
  info.created_by = j.value("created_by", std::string());
  try {
    const auto& a = j.at("axis");
    info.axis.origin_lps = vec3(a.at("origin_lps"));
    info.axis.direction = vec3(a.at("direction")).normalized();
    info.axis.front = vec3(a.at("front")).normalized();
    const auto& g = j.at("grid");
    info.grid.n_theta = to_int(g.at("n_theta").get<double>(), file.string() + ": grid.n_theta");
    info.grid.n_z = to_int(g.at("n_z").get<double>(), file.string() + ": grid.n_z");
    info.grid.theta0_deg = g.at("theta0_deg").get<double>();
    info.grid.z0_mm = g.at("z0_mm").get<double>();
    info.grid.dz_mm = g.at("dz_mm").get<double>();
  } catch (const json::exception& e) {
    throw InvalidInput(cat(file.string(), ": axis or grid is incomplete (", e.what(),
                           "); rebuild the model"));
  }
  const auto& g = info.grid;
  if (g.n_theta < 4 || g.n_z < 2 || !(g.dz_mm > 0))
    throw InvalidInput(cat(file.string(), ": grid ", g.n_theta, " x ", g.n_z, " with dz ",
                           g.dz_mm, " mm is not usable; rebuild the model"));
  auto text = [&](const char* key) { return j.contains(key) ? j[key].dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) : std::string("{}"); };
  info.source_json = text("source");
  info.segmentation_json = text("segmentation");
  info.thickness_json = text("thickness");
  info.stats = statistics_of(j.value("statistics", json::object()), file.string() + ": statistics");
  info.has_color = j.contains("files") && j["files"].contains("color");
  info.has_layers = j.contains("files") && j["files"].contains("thickness_skin");
  const json meshes = j.value("meshes", json::object());
  info.skin = mesh_summary_of(meshes.value("skin", json::object()), file.string() + ": meshes.skin");
  info.bone = mesh_summary_of(meshes.value("bone", json::object()), file.string() + ": meshes.bone");
  if (j.contains("content_hash") && j["content_hash"].is_string())
    info.content_hash = j["content_hash"].get<std::string>();
  if (j.contains("warnings") && j["warnings"].is_array())
    for (const auto& w : j["warnings"])
      if (w.is_string()) info.warnings.push_back(w.get<std::string>());
  if (j.contains("landmarks") && j["landmarks"].is_object())
    info.landmarks_json = j["landmarks"].dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  if (j.contains("features") && j["features"].is_object())
    info.features_json = j["features"].dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  return info;
}

}  // namespace

void write_model_landmarks(const fs::path& dir, const std::string& landmarks_json) {
  ModelInfo info = read_model_info(dir);
  parse_object(landmarks_json, "landmarks");
  info.landmarks_json = landmarks_json;
  write_text_atomic(dir / model_file::kJson, model_json_text(info));
}

void write_model_features(const fs::path& dir, const std::string& features_json) {
  ModelInfo info = read_model_info(dir);
  if (!parse_object(features_json, "features").is_object())
    throw InvalidInput(cat(dir.string(), ": the features to write into model.json are not a "
                           "JSON object"));
  info.features_json = features_json;
  write_text_atomic(dir / model_file::kJson, model_json_text(info));
}

std::string read_model_json(const fs::path& dir) {
  read_model_info(dir);
  return load_model_json(dir).dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
}

CylindricalMaps read_model_maps(const fs::path& dir, const ModelInfo& info) {
  namespace f = model_file;
  CylindricalMaps maps;
  maps.axis = info.axis;
  maps.grid = info.grid;
  const auto& g = maps.grid;
  maps.r_skin = read_map_nrrd(dir / f::kRSkin, g);
  maps.r_bone = read_map_nrrd(dir / f::kRBone, g);
  maps.thickness = read_map_nrrd(dir / f::kThickness, g);
  maps.thickness_normal = read_map_nrrd(dir / f::kThicknessNormal, g);
  const std::vector<float> flags = read_map_nrrd(dir / f::kValidity, g);
  maps.flags.resize(flags.size());
  maps.measured_skin.resize(flags.size());
  maps.measured_bone.resize(flags.size());
  for (std::size_t i = 0; i < flags.size(); ++i) {
    maps.flags[i] = static_cast<std::uint8_t>(flags[i]);
    maps.measured_skin[i] = !(maps.flags[i] & kNoSkin);
    maps.measured_bone[i] = !(maps.flags[i] & (kNoSkin | kNoBone));
  }
  if (info.has_layers) {
    maps.thickness_skin = read_map_nrrd(dir / f::kThicknessSkin, g);
    maps.thickness_fat = read_map_nrrd(dir / f::kThicknessFat, g);
    maps.thickness_deep = read_map_nrrd(dir / f::kThicknessDeep, g);
    maps.thickness_skin_normal = read_map_nrrd(dir / f::kThicknessSkinNormal, g);
    maps.thickness_fat_normal = read_map_nrrd(dir / f::kThicknessFatNormal, g);
    maps.thickness_deep_normal = read_map_nrrd(dir / f::kThicknessDeepNormal, g);
    for (auto [file, out] : {std::pair{f::kLayerValidity, &maps.layer_flags},
                             std::pair{f::kLayerValidityNormal, &maps.layer_flags_normal}}) {
      const std::vector<float> v = read_map_nrrd(dir / file, g);
      out->assign(v.begin(), v.end());
    }
  }
  return maps;
}

RgbImage read_model_color(const fs::path& dir, const ModelInfo& info) {
  if (!info.has_color) return {};
  const fs::path file = dir / model_file::kColor;
  RgbImage color = read_png(file);
  const auto& g = info.grid;
  if (color.width != g.n_theta || color.height != g.n_z)
    throw InvalidInput(cat(file.string(), ": ", color.width, " x ", color.height,
                           " pixels, expected the grid's ", g.n_theta, " x ", g.n_z));
  return color;
}

std::string content_hash(const CylindricalMaps& maps) {
  std::uint64_t h = 1469598103934665603ull;  // FNV-1a, 64 bit
  auto add = [&h](const void* data, std::size_t n) {
    const auto* b = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  };
  const auto& g = maps.grid;
  const double grid[] = {double(g.n_theta), double(g.n_z), g.theta0_deg, g.z0_mm, g.dz_mm};
  add(grid, sizeof grid);
  for (const auto* v : {&maps.r_skin, &maps.r_bone, &maps.thickness})
    add(v->data(), v->size() * sizeof(float));
  add(maps.flags.data(), maps.flags.size() * sizeof(maps.flags[0]));
  char text[32];
  std::snprintf(text, sizeof text, "fnv1a64:%016llx", static_cast<unsigned long long>(h));
  return text;
}

namespace {

// The tissue layer maps, their validity and a picture of each (along the normal).
void write_layers(const fs::path& p, const CylindricalMaps& maps, const ModelProvenance& c) {
  namespace f = model_file;
  const auto& g = maps.grid;
  const char* kFlags = "0 measured; bit flags 1 no_thickness, 2 no_fat, 4 several_fat_bands, "
                       "8 no_contrast, 16 thin_skin";
  write_map_nrrd(p / f::kThicknessSkin, maps.thickness_skin, g,
                 "thickness_skin: skin to the top of the subcutaneous fat, radial", "mm");
  write_map_nrrd(p / f::kThicknessFat, maps.thickness_fat, g,
                 "thickness_fat: subcutaneous fat, radial", "mm");
  write_map_nrrd(p / f::kThicknessDeep, maps.thickness_deep, g,
                 "thickness_deep: the fat's bottom to the bone, radial", "mm");
  write_map_nrrd(p / f::kThicknessSkinNormal, maps.thickness_skin_normal, g,
                 "thickness_skin_normal: skin to the fat, towards the nearest bone", "mm");
  write_map_nrrd(p / f::kThicknessFatNormal, maps.thickness_fat_normal, g,
                 "thickness_fat_normal: subcutaneous fat, towards the nearest bone", "mm");
  write_map_nrrd(p / f::kThicknessDeepNormal, maps.thickness_deep_normal, g,
                 "thickness_deep_normal: the fat to the nearest bone", "mm");
  for (auto [file, flags, what] :
       {std::tuple{f::kLayerValidity, &maps.layer_flags, "layer_validity (radial)"},
        std::tuple{f::kLayerValidityNormal, &maps.layer_flags_normal, "layer_validity_normal"}}) {
    const std::vector<float> v(flags->begin(), flags->end());
    write_map_nrrd(p / file, v, g, cat(what, ": ", kFlags), "flags");
  }
  write_layer_png(p / f::kLayerSkinPng, maps, maps.thickness_skin_normal, maps.layer_flags_normal,
                  "skin: surface to the fat (mm)",
                  cat("Skin (dermis) to the subcutaneous fat, along the normal, ", c.name), c.credit);
  // No fat seen is a measurement of the fat (0 mm), not of where the skin ends.
  std::vector<std::uint8_t> fat_flags = maps.layer_flags_normal;
  for (auto& fl : fat_flags) fl &= static_cast<std::uint8_t>(~kLayerNoFat);
  write_layer_png(p / f::kLayerFatPng, maps, maps.thickness_fat_normal, fat_flags,
                  "subcutaneous fat (mm)", cat("Subcutaneous fat, along the normal, ", c.name),
                  c.credit);
  write_layer_png(p / f::kLayerDeepPng, maps, maps.thickness_deep_normal, maps.layer_flags_normal,
                  "deep tissue: fat to bone (mm)",
                  cat("Deep tissue (fat to bone), along the normal, ", c.name), c.credit);
}

}  // namespace

void write_model_directory(const ModelContent& m, const ModelProvenance& c, const fs::path& dir,
                           bool force, Reporter* reporter) {
  namespace f = model_file;
  const auto& maps = m.maps;
  const auto& g = maps.grid;
  const bool has_color = !m.color.empty();
  if (has_color && (m.color.width != g.n_theta || m.color.height != g.n_z ||
                    m.color.rgb.size() != g.size() * 3))
    throw InvalidInput(cat("write_model_directory: the colour image is ", m.color.width, " x ",
                           m.color.height, ", expected the grid's ", g.n_theta, " x ", g.n_z));
  ModelInfo info;
  info.axis = maps.axis;
  info.grid = g;
  info.source_json = c.source_json;
  info.segmentation_json = c.segmentation_json;
  info.thickness_json = c.thickness_json;
  info.stats = m.stats;
  info.has_color = has_color;
  info.has_layers = maps.has_layers();
  info.skin = summary_of(m.skin);
  info.bone = summary_of(m.bone);
  info.content_hash = content_hash(maps);
  if (reporter) info.warnings = reporter->warnings();
  const std::string model_json = model_json_text(info);  // checks the JSON before writing

  OutputDirectory out(dir, force);
  const fs::path p = out.path();
  Progress progress(reporter, "writing the model", 8);
  write_map_nrrd(p / f::kRSkin, maps.r_skin, g, "r_skin: skin radius", "mm");
  write_map_nrrd(p / f::kRBone, maps.r_bone, g, "r_bone: bone radius", "mm");
  write_map_nrrd(p / f::kThickness, maps.thickness, g, "thickness: radial soft tissue", "mm");
  write_map_nrrd(p / f::kThicknessNormal, maps.thickness_normal, g,
                 "thickness_normal: skin to nearest bone", "mm");
  std::vector<float> flags(maps.flags.begin(), maps.flags.end());
  write_map_nrrd(p / f::kValidity, flags, g,
                 "validity: 0 valid; bit flags 1 no_skin, 2 no_bone, 4 undercut, 8 grazing, "
                 "16 truncated; 32 base_cavity (valid, its base an air cavity's edge); 64 eye; "
                 "128 base_tissue (valid, its base on deeper tissue at an interpolated depth)",
                 "flags");
  progress.update(3);
  // Clinicians and the soft-tissue-depth literature read the thickness along the normal.
  const bool assumed_bone = parse_object(c.thickness_json, "thickness").value("kind", "") ==
                            std::string("approximate");
  write_thickness_png(p / f::kThicknessPng, maps, maps.thickness_normal,
                      cat("Soft-tissue thickness along the normal (skin to nearest bone), ", c.name,
                          assumed_bone ? "; bone ASSUMED (MR: no bone signal)" : ""),
                      c.credit);
  // The layers' maps and pictures are written beside the rest (2 s budget, docs/benchmarks.md).
  tbb::task_group layers;
  if (maps.has_layers()) layers.run([&] { write_layers(p, maps, c); });
  write_skin_png(p / f::kSkinPng, maps, cat("Skin range image (shaded), ", c.name), c.credit);
  if (has_color) write_png(p / f::kColor, m.color);
  progress.update(5);
  write_ply(m.skin, p / f::kSkinMesh);
  write_ply(m.bone, p / f::kBoneMesh);
  layers.wait();
  progress.update(7);
  write_text_atomic(p / f::kJson, model_json);
  out.commit();
}

namespace {

// ", found along the rays by its edge (floor 150 HU)" when model.json's thickness.base says so.
std::string bone_along_rays(const ModelInfo& info) {
  const json t = parse_object(info.thickness_json, "thickness");
  if (!t.contains("base") || !t["base"].is_object()) return {};
  const json& b = t["base"];
  if (b.value("bone_method", "") != "edge") return {};
  return cat("; along the rays by its edge (a peak ", b.value("floor_hu", 0.0),
             " HU above the soft tissue)");
}

}  // namespace

std::string model_summary(const fs::path& dir) {
  const ModelInfo info = read_model_info(dir);
  const json source = parse_object(info.source_json, "source");
  const json seg = parse_object(info.segmentation_json, "segmentation");
  const auto& s = info.stats;
  const auto& g = info.grid;
  // A key the summary prints: a damaged model.json names it (not "key 'path' not found").
  const auto text = [&](const json& j, const char* group, const char* key) {
    const auto it = j.find(key);
    if (it == j.end() || !it->is_string())
      throw InvalidInput(cat((dir / model_file::kJson).string(), ": ", group, ".", key, " is ",
                             it == j.end() ? "missing" : "not a text",
                             "; the model folder is damaged: rebuild it (caps model from-volume)"));
    return it->get<std::string>();
  };
  std::ostringstream os;
  os.precision(3);
  os << "model      " << dir.string() << " (format " << info.format_version << ")\n"
     << "source     " << text(source, "source", "path") << " ("
     << text(source, "source", "format") << ", " << text(source, "source", "modality") << ")\n"
     << "grid       " << g.n_theta << " x " << g.n_z << " (theta x z), dz " << g.dz_mm
     << " mm, z " << g.z0_mm << " .. " << g.z_mm(g.n_z - 1) << " mm\n"
     << "skin       " << text(seg, "segmentation", "skin_method") << "\n"
     << "bone       " << text(seg, "segmentation", "bone_method") << bone_along_rays(info)
     << "\n"
     << "valid      " << 100.0 * (s.cells ? double(s.valid_cells) / s.cells : 0.0)
     << " % of cells"
     << (s.base_cavity || s.base_tissue
             ? cat(" (", s.base_cavity, " based on an air cavity, ", s.base_tissue,
                   " on deeper tissue)")
             : "")
     << "\n"
     << "thickness  median " << s.thickness_median_mm << " mm (5-95%: " << s.thickness_p5_mm
     << " - " << s.thickness_p95_mm << " mm), forehead " << s.forehead_thickness_mm << " mm\n"
     << "face       theta " << s.face_theta_deg << " deg, z " << s.face_z_mm << " mm\n";
  // Metal (models built since 5 December; older ones were not examined and say nothing).
  if (const auto m = seg.find("metal"); m != seg.end() && m->is_object() &&
                                        m->value("checked", false)) {
    if (!m->value("found", false)) {
      os << "metal      none (no voxel group at or above "
         << std::lround(m->value("threshold_hu", 0.0)) << " HU)\n";
    } else {
      const json cells = m->value("cells", json::object());
      const json z = cells.value("z_mm", json::array());
      os << "metal      found: " << m->value("pieces", 0) << " piece(s), "
         << std::lround(m->value("volume_mm3", 0.0)) << " mm3; its streaks removed, "
         << cells.value("count", 0) << " cells marked not valid (truncated)";
      if (z.is_array() && z.size() == 2 && z[0].is_number() && z[1].is_number())
        os << " at z " << z[0].get<double>() << " .. " << z[1].get<double>() << " mm";
      os << "\n";
    }
  }
  if (info.has_layers)
    os << "layers     median skin " << s.skin_layer_median_mm << " mm, fat " << s.fat_median_mm
       << " mm, deep " << s.deep_median_mm << " mm over " << s.layer_cells << " cells (no fat "
       << s.no_fat << ", several fat bands " << s.several_fat_bands << ")\n";
  return os.str();
}

}  // namespace caps

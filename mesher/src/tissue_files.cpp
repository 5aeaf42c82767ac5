// The tissue model's files in a model directory: tissue.vtu (VTK XML unstructured grid, ASCII),
// tissue.json (provenance), skin.vdb and bone.vdb (the level sets).
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/mesher/tissue_model.hpp"

namespace caps::mesher {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr char kNoModel[] =
    "the model has no whole-face tissue model: run `caps model tissue MODEL`";
constexpr std::uintmax_t kMaxVtuBytes = std::uintmax_t(1) << 30;  // 1 GiB: about 10 M tets
constexpr std::uintmax_t kMaxJsonBytes = 1 << 20;

void require(const fs::path& dir, const char* name) {
  if (!fs::exists(dir / name)) throw InvalidInput(cat(dir.string(), ": ", kNoModel));
}

std::string tissue_json_text(const TissueModel& m) {
  const TissueModelOptions& o = m.options;
  json j;
  j["format"] = "caps tissue model";
  j["format_version"] = 1;
  j["method"] = m.method;
  j["source"] = m.source;
  j["files"] = {{"mesh", tissue_file::kMesh},
                {"skin_level_set", tissue_file::kSkinLevelSet},
                {"bone_level_set", tissue_file::kBoneLevelSet}};
  j["counts"] = {{"nodes", m.n_nodes()},
                 {"tets", m.n_tets()},
                 {"skin_nodes", m.count_nodes(kTissueOnSkin)},
                 {"bone_nodes", m.count_nodes(kTissueOnBone)},
                 {"field_of_view_nodes", m.count_nodes(kTissueFieldOfView)},
                 {"other_boundary_nodes", m.count_nodes(kTissueOtherBoundary)}};
  j["sizes_mm"] = {{"face_facet", o.face_size_mm},
                   {"scalp_facet", o.scalp_size_mm},
                   {"face_half_angle_deg", o.face_half_angle_deg},
                   {"face_blend_deg", o.face_blend_deg},
                   {"cell_growth_per_mm_depth", o.cell_growth},
                   {"facet_distance_fraction", o.facet_distance_fraction},
                   {"depth_limit", o.depth_limit_mm},
                   {"band", o.band_mm},
                   {"label_voxel", {m.label_voxel_mm[0], m.label_voxel_mm[1], m.label_voxel_mm[2]}},
                   {"level_set_voxel", m.level_set_voxel_mm}};
  j["volume_ml"] = m.volume_ml;
  j["layer_volume_ml"] = {{"dermis", m.layer_volume_ml[0]},
                          {"fat", m.layer_volume_ml[1]},
                          {"deep", m.layer_volume_ml[2]}};
  j["layer_fallback_fraction"] = m.layer_fallback_fraction;
  j["timings_s"] = {{"level_sets", m.seconds_level_sets},
                    {"labels", m.seconds_labels},
                    {"mesh", m.seconds_mesh},
                    {"layers", m.seconds_layers},
                    {"total", m.seconds_total}};
  j["node_flags"] = {{"on_skin", kTissueOnSkin},
                     {"on_bone", kTissueOnBone},
                     {"field_of_view", kTissueFieldOfView},
                     {"other_boundary", kTissueOtherBoundary}};
  j["warnings"] = m.warnings;
  return j.dump(2) + "\n";
}

// A cursor over the VTU text: finds tags and reads the numbers of one DataArray.
struct VtuText {
  const std::string& s;
  const std::string& where;

  [[noreturn]] void bad(const std::string& what) const {
    throw InvalidInput(cat(where, ": ", what,
                           "; not a tissue model caps wrote (rebuild it with "
                           "`caps model tissue MODEL --force`)"));
  }
  std::size_t find(const std::string& key, std::size_t from = 0) const {
    const std::size_t p = s.find(key, from);
    if (p == std::string::npos) bad(cat("no ", key));
    return p;
  }
  long long attribute(std::size_t tag, const std::string& name) const {
    const std::size_t end = find(">", tag);
    const std::size_t p = s.find(name + "=\"", tag);
    if (p == std::string::npos || p > end) bad(cat("no ", name));
    char* stop = nullptr;
    const long long v = std::strtoll(s.c_str() + p + name.size() + 2, &stop, 10);
    if (v < 0) bad(cat(name, " negative"));
    return v;
  }
  // The `count` numbers of the DataArray named `name`.
  template <class T>
  std::vector<T> array(const std::string& name, std::size_t count) const {
    const std::size_t tag = find("Name=\"" + name + "\"");
    std::size_t p = find(">", tag) + 1;
    const std::size_t end = find("</DataArray>", p);
    std::vector<T> out;
    // Each value takes at least two characters of the array's text.
    out.reserve(std::min(count, (end - p) / 2 + 1));
    const char* c = s.c_str() + p;
    const char* e = s.c_str() + end;
    while (c < e) {
      while (c < e && std::isspace(static_cast<unsigned char>(*c))) ++c;
      if (c >= e) break;
      char* stop = nullptr;
      const double v = std::strtod(c, &stop);
      if (stop == c || stop > e) bad(cat("a value of ", name, " is not a number"));
      if (out.size() == count) bad(cat(name, " holds more than ", count, " values"));
      out.push_back(static_cast<T>(v));
      if (!std::isfinite(v)) bad(cat(name, " holds a non-finite value"));
      c = stop;
    }
    if (out.size() != count) bad(cat(name, " holds ", out.size(), " values, not ", count));
    return out;
  }
};

}  // namespace

void write_tissue_model(const fs::path& dir, const TissueModel& m, const TissueLevelSets& ls) {
  if (!fs::is_directory(dir)) throw IoError(cat(dir.string(), ": no such model directory"));
  const Eigen::Index n = m.n_nodes(), t = m.n_tets();
  const std::vector<int> dominant = m.dominant_layer();
  write_file_atomic(dir / tissue_file::kMesh, [&](const fs::path& tmp) {
    std::FILE* f = std::fopen(tmp.c_str(), "w");
    if (!f) throw IoError(cat(tmp.string(), ": cannot write"));
    std::fprintf(f,
                 "<?xml version=\"1.0\"?>\n<!-- caps whole-face tissue model: LPS mm; "
                 "node_flags 1 skin, 2 bone, 4 field of view, 8 other boundary; layers dermis, "
                 "fat, deep -->\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" "
                 "byte_order=\"LittleEndian\" header_type=\"UInt64\">\n<UnstructuredGrid>\n"
                 "<Piece NumberOfPoints=\"%lld\" NumberOfCells=\"%lld\">\n",
                 static_cast<long long>(n), static_cast<long long>(t));
    std::fprintf(f,
                 "<PointData Scalars=\"node_flags\">\n"
                 "<DataArray type=\"UInt8\" Name=\"node_flags\" format=\"ascii\">\n");
    for (Eigen::Index v = 0; v < n; ++v)
      std::fprintf(f, "%d%c", m.node_flags[static_cast<std::size_t>(v)], v % 20 == 19 ? '\n' : ' ');
    std::fprintf(f,
                 "\n</DataArray>\n</PointData>\n<CellData Scalars=\"dominant_layer\">\n"
                 "<DataArray type=\"Float32\" Name=\"layer_fraction\" "
                 "NumberOfComponents=\"3\" format=\"ascii\">\n");
    for (Eigen::Index c = 0; c < t; ++c)
      std::fprintf(f, "%.6g %.6g %.6g\n", m.layer_fraction(c, 0), m.layer_fraction(c, 1),
                   m.layer_fraction(c, 2));
    std::fprintf(f,
                 "</DataArray>\n<DataArray type=\"Int32\" Name=\"dominant_layer\" "
                 "format=\"ascii\">\n");
    for (Eigen::Index c = 0; c < t; ++c)
      std::fprintf(f, "%d%c", dominant[static_cast<std::size_t>(c)], c % 20 == 19 ? '\n' : ' ');
    std::fprintf(f,
                 "\n</DataArray>\n</CellData>\n<Points>\n<DataArray type=\"Float64\" "
                 "Name=\"Points\" NumberOfComponents=\"3\" format=\"ascii\">\n");
    for (Eigen::Index v = 0; v < n; ++v)
      std::fprintf(f, "%.17g %.17g %.17g\n", m.nodes(v, 0), m.nodes(v, 1), m.nodes(v, 2));
    std::fprintf(f,
                 "</DataArray>\n</Points>\n<Cells>\n<DataArray type=\"Int64\" "
                 "Name=\"connectivity\" format=\"ascii\">\n");
    for (Eigen::Index c = 0; c < t; ++c)
      std::fprintf(f, "%d %d %d %d\n", m.tets(c, 0), m.tets(c, 1), m.tets(c, 2), m.tets(c, 3));
    std::fprintf(f, "</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
    for (Eigen::Index c = 0; c < t; ++c)
      std::fprintf(f, "%lld%c", 4LL * (c + 1), c % 20 == 19 ? '\n' : ' ');
    std::fprintf(f, "\n</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
    for (Eigen::Index c = 0; c < t; ++c) std::fprintf(f, "10%c", c % 40 == 39 ? '\n' : ' ');
    std::fprintf(f, "\n</DataArray>\n</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");
    const bool ok = std::ferror(f) == 0;
    if (std::fclose(f) != 0 || !ok) throw IoError(cat(tmp.string(), ": write failed"));
  });
  ls.skin.write(dir / tissue_file::kSkinLevelSet, "skin");
  ls.bone.write(dir / tissue_file::kBoneLevelSet, "bone");
  write_text_atomic(dir / tissue_file::kJson, tissue_json_text(m));
}

bool has_tissue_model(const fs::path& dir) { return fs::exists(dir / tissue_file::kMesh); }

TissueModel read_tissue_model(const fs::path& dir) {
  require(dir, tissue_file::kMesh);
  const fs::path path = dir / tissue_file::kMesh;
  const std::string where = path.string();
  std::error_code ec;
  const std::uintmax_t bytes = fs::file_size(path, ec);
  if (ec) throw IoError(cat(where, ": cannot read (", ec.message(), ")"));
  if (bytes > kMaxVtuBytes)
    throw InvalidInput(cat(where, ": ", bytes, " bytes, more than a tissue model's limit of ",
                           kMaxVtuBytes, "; not a tissue model caps wrote"));
  std::string text(static_cast<std::size_t>(bytes), '\0');
  {
    std::ifstream in(path, std::ios::binary);
    if (!in || !in.read(text.data(), static_cast<std::streamsize>(bytes)))
      throw IoError(cat(where, ": cannot read"));
  }
  const VtuText vtu{text, where};
  if (text.find("caps whole-face tissue model") == std::string::npos ||
      text.find("<VTKFile type=\"UnstructuredGrid\"") == std::string::npos)
    vtu.bad("not a caps tissue model (VTK unstructured grid)");
  const std::size_t piece = vtu.find("<Piece");
  const long long n = vtu.attribute(piece, "NumberOfPoints");
  const long long t = vtu.attribute(piece, "NumberOfCells");
  // Every value takes at least two characters: the counts cannot exceed the file's length.
  if (n < 4 || t < 1 || static_cast<std::uintmax_t>(3 * n + 9 * t) > bytes / 2)
    vtu.bad(cat(n, " points and ", t, " cells do not fit in ", bytes, " bytes"));
  const std::size_t nn = static_cast<std::size_t>(n), nt = static_cast<std::size_t>(t);
  TissueModel m;
  const auto points = vtu.array<double>("Points", 3 * nn);
  const auto conn = vtu.array<long long>("connectivity", 4 * nt);
  const auto offsets = vtu.array<long long>("offsets", nt);
  const auto types = vtu.array<int>("types", nt);
  const auto flags = vtu.array<int>("node_flags", nn);
  const auto frac = vtu.array<float>("layer_fraction", 3 * nt);
  m.nodes.resize(n, 3);
  for (std::size_t v = 0; v < nn; ++v)
    for (int a = 0; a < 3; ++a) m.nodes(static_cast<Eigen::Index>(v), a) = points[3 * v + a];
  m.tets.resize(t, 4);
  m.layer_fraction.resize(t, 3);
  for (std::size_t c = 0; c < nt; ++c) {
    if (types[c] != 10 || offsets[c] != 4LL * static_cast<long long>(c + 1))
      vtu.bad(cat("cell ", c, " is not a linear tetrahedron (type ", types[c], ")"));
    for (int q = 0; q < 4; ++q) {
      const long long id = conn[4 * c + q];
      if (id < 0 || id >= n) vtu.bad(cat("cell ", c, " names point ", id, " of ", n));
      m.tets(static_cast<Eigen::Index>(c), q) = static_cast<int>(id);
    }
    if (!(tet_volume(m.nodes, m.tets.row(static_cast<Eigen::Index>(c)).transpose()) > 0))
      vtu.bad(cat("cell ", c, " has no positive volume"));
    float sum = 0;
    for (int l = 0; l < 3; ++l) {
      const float f = frac[3 * c + l];
      if (!(f >= 0 && f <= 1)) vtu.bad(cat("cell ", c, ": layer fraction ", f, " not in [0, 1]"));
      m.layer_fraction(static_cast<Eigen::Index>(c), l) = f;
      sum += f;
    }
    if (std::abs(sum - 1.0f) > 1e-3f) vtu.bad(cat("cell ", c, ": layer fractions sum to ", sum));
  }
  m.node_flags.resize(nn);
  for (std::size_t v = 0; v < nn; ++v) {
    if (flags[v] < 0 || flags[v] > 15) vtu.bad(cat("node ", v, ": flags ", flags[v]));
    m.node_flags[v] = static_cast<std::uint8_t>(flags[v]);
  }
  double total = 0;
  for (Eigen::Index c = 0; c < t; ++c) {
    const double v = tet_volume(m.nodes, m.tets.row(c).transpose());
    total += v;
    for (int l = 0; l < 3; ++l) m.layer_volume_ml[l] += 1e-3 * v * m.layer_fraction(c, l);
  }
  m.volume_ml = 1e-3 * total;
  // Provenance, where tissue.json is there and readable.
  const fs::path jpath = dir / tissue_file::kJson;
  if (fs::exists(jpath) && fs::file_size(jpath, ec) < kMaxJsonBytes && !ec) {
    std::ifstream in(jpath);
    const json j = json::parse(in, nullptr, false);
    if (j.is_object()) {
      m.method = j.value("method", std::string());
      m.source = j.value("source", std::string());
      if (j.contains("warnings") && j["warnings"].is_array())
        for (const auto& w : j["warnings"])
          if (w.is_string()) m.warnings.push_back(w.get<std::string>());
      if (j.contains("sizes_mm") && j["sizes_mm"].is_object()) {
        const json& s = j["sizes_mm"];
        m.options.face_size_mm = s.value("face_facet", m.options.face_size_mm);
        m.options.scalp_size_mm = s.value("scalp_facet", m.options.scalp_size_mm);
        m.options.depth_limit_mm = s.value("depth_limit", m.options.depth_limit_mm);
        m.level_set_voxel_mm = s.value("level_set_voxel", 0.0);
        const json lv = s.value("label_voxel", json::array());
        if (lv.is_array() && lv.size() == 3)
          for (int a = 0; a < 3; ++a)
            if (lv[a].is_number()) m.label_voxel_mm[a] = std::clamp(lv[a].get<double>(), 0.0, 100.0);
      }
      if (j.contains("timings_s") && j["timings_s"].is_object())
        m.seconds_total = j["timings_s"].value("total", 0.0);
    }
  }
  return m;
}

SignedDistanceField read_bone_level_set(const fs::path& dir) {
  require(dir, tissue_file::kBoneLevelSet);
  return SignedDistanceField::read(dir / tissue_file::kBoneLevelSet);
}

SignedDistanceField read_skin_level_set(const fs::path& dir) {
  require(dir, tissue_file::kSkinLevelSet);
  return SignedDistanceField::read(dir / tissue_file::kSkinLevelSet);
}

}  // namespace caps::mesher

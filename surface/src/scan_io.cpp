#include "caps/surface/scan_io.hpp"

#include <tiny_gltf.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <new>
#include <sstream>

#include "caps/core/checked_numbers.hpp"
#include "caps/core/error.hpp"
#include "caps/core/file_access.hpp"
#include "caps/core/json_limits.hpp"
#include "caps/volume/mesh_io.hpp"

namespace fs = std::filesystem;

namespace caps {
namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

// Opens a scan file and starts its ScanMesh (source and format).
std::ifstream open_scan(const fs::path& path, const char* format, ScanMesh& s,
                        std::ios::openmode mode = std::ios::in) {
  require_readable(path, false, "check the path and its permissions");
  std::ifstream in(path, mode);
  if (!in) throw IoError(cat(path.string(), ": cannot open (missing or unreadable)"));
  s.source = path.string();
  s.format = format;
  return in;
}

// The triangles, checked against the `n_vertices` vertices; `what` names a bad one.
void set_faces(ScanMesh& s, const std::vector<Eigen::Vector3i>& F, Eigen::Index n_vertices,
               const char* what = "a face refers to a vertex") {
  s.mesh.F.resize(static_cast<Eigen::Index>(F.size()), 3);
  for (std::size_t i = 0; i < F.size(); ++i) s.mesh.F.row(i) = F[i].transpose();
  if (s.mesh.n_faces() > 0 && (s.mesh.F.minCoeff() < 0 || s.mesh.F.maxCoeff() >= n_vertices))
    throw InvalidInput(cat(s.source, ": ", what, " that does not exist"));
}

// Finishes a scan: checks the texture coordinates refer to existing rows and applies flip_v.
void finish(ScanMesh& s, const ScanReadOptions& o) {
  if (!o.texture.empty()) {
    s.texture = read_image(o.texture);
    s.texture_source = o.texture.string();
  }
  if (o.flip_v && s.UV.rows() > 0) s.UV.col(1) = (1.0 - s.UV.col(1).array()).matrix();
  if (s.mesh.n_faces() == 0)
    throw InvalidInput(cat(s.source, ": the mesh has no faces; a scan must be a surface of "
                               "triangles or polygons, not a point cloud"));
  if (s.FUV.rows() > 0) {
    if (s.FUV.rows() != s.mesh.n_faces())
      throw InvalidInput(cat(s.source, ": texture coordinates for ", s.FUV.rows(), " of ",
                             s.mesh.n_faces(), " faces"));
    if (s.FUV.minCoeff() < 0 || s.FUV.maxCoeff() >= s.UV.rows())
      throw InvalidInput(cat(s.source, ": a texture coordinate index is out of range"));
  }
}

// ---- glTF 2.0

// The most vertices a glTF scene may add up to over all its mesh instances (24 bytes each).
constexpr std::size_t kMaxGltfVertices = 10'000'000;
// The largest external buffer or image file a .gltf may name (its vertices, at most
// kMaxGltfVertices, and a texture fit in far less).
constexpr std::uintmax_t kMaxGltfExternalBytes = std::uintmax_t(2) << 30;

// tinygltf's access to the files a .gltf names (its external buffers and images), instead of
// its own: only regular files, at most kMaxGltfExternalBytes, and paths taken as they are. Its
// own reader sized a buffer named "data" that was a folder from tellg()'s -1 (an allocation of
// 2^63 bytes: fuzz_gltf, kept in fuzz/regressions/fuzz_gltf) and would block on a FIFO or a
// device; its own path expansion runs wordexp on the name.
bool gltf_file_exists(const std::string& path, void*) {
  std::error_code ec;
  return fs::is_regular_file(path, ec);
}

std::string gltf_expand_path(const std::string& path, void*) { return path; }

bool gltf_read_file(std::vector<unsigned char>* out, std::string* err, const std::string& path,
                    void*) {
  std::error_code ec;
  const bool regular = fs::is_regular_file(path, ec);
  const std::uintmax_t bytes = regular ? fs::file_size(path, ec) : 0;
  if (!regular || ec) {
    if (err)
      *err += cat("'", path, "' is not a file (a glTF's buffers and images must be files)\n");
    return false;
  }
  if (bytes > kMaxGltfExternalBytes) {
    if (err)
      *err += cat("'", path, "' has ", bytes, " bytes, more than a scan's buffer or image may (",
                  kMaxGltfExternalBytes, ")\n");
    return false;
  }
  std::ifstream in(path, std::ios::binary);
  out->resize(static_cast<std::size_t>(bytes));
  if (!in || !in.read(reinterpret_cast<char*>(out->data()), static_cast<std::streamsize>(bytes))) {
    if (err) *err += cat("'", path, "' could not be read\n");
    return false;
  }
  return true;
}

bool gltf_refuse_write(std::string* err, const std::string& path,
                       const std::vector<unsigned char>&, void*) {
  if (err) *err += cat("'", path, "': reading a scan writes no file\n");
  return false;
}

Eigen::Matrix4d node_matrix(const tinygltf::Node& n) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  if (n.matrix.size() == 16) {
    for (int c = 0; c < 4; ++c)
      for (int r = 0; r < 4; ++r) m(r, c) = n.matrix[c * 4 + r];
    return m;
  }
  Eigen::Affine3d a = Eigen::Affine3d::Identity();
  if (n.translation.size() == 3) a.translate(Eigen::Vector3d(n.translation[0], n.translation[1], n.translation[2]));
  if (n.rotation.size() == 4)
    a.rotate(Eigen::Quaterniond(n.rotation[3], n.rotation[0], n.rotation[1], n.rotation[2]));
  if (n.scale.size() == 3) a.scale(Eigen::Vector3d(n.scale[0], n.scale[1], n.scale[2]));
  return a.matrix();
}

// Reads accessor element i, component c, as double (normalised integers scaled to [0, 1]).
struct AccessorView {
  const unsigned char* base = nullptr;
  std::size_t stride = 0, count = 0;
  int components = 0, type = 0;
  bool normalized = false;
  /// NaN for a component the accessor does not have (a VEC2 read as a position; the callers
  /// refuse non-finite values): reading it would run past the element (found by fuzz_gltf).
  double get(std::size_t i, int c) const {
    if (c < 0 || c >= components || i >= count) return std::nan("");
    const unsigned char* p = base + i * stride;
    switch (type) {
      case TINYGLTF_COMPONENT_TYPE_FLOAT: { float v; std::memcpy(&v, p + 4 * c, 4); return v; }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: { const double v = p[c]; return normalized ? v / 255.0 : v; }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { std::uint16_t v; std::memcpy(&v, p + 2 * c, 2); return normalized ? v / 65535.0 : v; }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: { std::uint32_t v; std::memcpy(&v, p + 4 * c, 4); return v; }
      default: return std::nan("");
    }
  }
};

AccessorView view_of(const tinygltf::Model& model, int index, const std::string& where) {
  if (index < 0 || index >= static_cast<int>(model.accessors.size()))
    throw InvalidInput(cat(where, ": accessor ", index, " does not exist"));
  const auto& acc = model.accessors[index];
  if (acc.bufferView < 0 || acc.bufferView >= static_cast<int>(model.bufferViews.size()))
    throw InvalidInput(cat(where, ": accessor ", index, " has no buffer view (sparse accessors are "
                               "not supported)"));
  const auto& bv = model.bufferViews[acc.bufferView];
  if (bv.buffer < 0 || bv.buffer >= static_cast<int>(model.buffers.size()))
    throw InvalidInput(cat(where, ": accessor ", index, " names buffer ", bv.buffer,
                           ", which does not exist"));
  const auto& buf = model.buffers[bv.buffer];
  AccessorView v;
  v.components = tinygltf::GetNumComponentsInType(acc.type);
  const int size = tinygltf::GetComponentSizeInBytes(acc.componentType);
  if (v.components <= 0 || size <= 0) throw InvalidInput(cat(where, ": accessor ", index, " has an unknown type"));
  v.type = acc.componentType;
  v.normalized = acc.normalized;
  v.count = acc.count;
  v.stride = acc.ByteStride(bv) > 0 ? acc.ByteStride(bv) : std::size_t(v.components * size);
  // Declared counts and offsets can be anything up to 2^64: compare without overflowing.
  const std::size_t n = buf.data.size(), elem = std::size_t(v.components) * std::size_t(size);
  const bool fits = bv.byteOffset <= n && acc.byteOffset <= n - bv.byteOffset &&
                    elem <= n - bv.byteOffset - acc.byteOffset && v.stride > 0 &&
                    (v.count == 0 ||
                     v.count - 1 <= (n - bv.byteOffset - acc.byteOffset - elem) / v.stride);
  const std::size_t offset = fits ? bv.byteOffset + acc.byteOffset : 0;
  if (!fits)
    throw InvalidInput(cat(where, ": accessor ", index, " runs past the end of its buffer; the file "
                               "is truncated"));
  v.base = buf.data.data() + offset;
  return v;
}

RgbImage to_rgb(const tinygltf::Image& im, const std::string& where) {
  if (im.image.empty() || im.width <= 0 || im.height <= 0 || im.component < 3 || im.bits != 8)
    throw IoError(cat(where, ": the texture '", im.uri.empty() ? im.name : im.uri,
                      "' could not be decoded; give one with --texture"));
  RgbImage out;
  out.width = im.width;
  out.height = im.height;
  out.rgb.resize(std::size_t(im.width) * im.height * 3);
  for (std::size_t i = 0; i < std::size_t(im.width) * im.height; ++i)
    for (int c = 0; c < 3; ++c) out.rgb[i * 3 + c] = im.image[i * im.component + c];
  return out;
}

ScanMesh read_gltf(const fs::path& path, const ScanReadOptions& o) {
  tinygltf::TinyGLTF loader;
  loader.SetFsCallbacks(
      {gltf_file_exists, gltf_expand_path, gltf_read_file, gltf_refuse_write, nullptr});
  tinygltf::Model model;
  std::string err, warn;
  const bool binary = lower(path.extension().string()) == ".glb";
  {
    // tinygltf parses the JSON (the chunk of a .glb) into a tree: bound its nesting first.
    std::ifstream in(path, std::ios::binary);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (binary && text.size() >= 20) {
      std::uint32_t length = 0;
      std::memcpy(&length, text.data() + 12, 4);
      text = text.substr(20, length);
    }
    check_json_depth(text, path.string());
  }
  const bool ok = binary ? loader.LoadBinaryFromFile(&model, &err, &warn, path.string())
                         : loader.LoadASCIIFromFile(&model, &err, &warn, path.string());
  if (!ok) throw IoError(cat(path.string(), ": cannot read glTF (", err.empty() ? warn : err, ")"));
  ScanMesh s;
  s.source = path.string();
  s.format = "glTF";
  s.mm_per_unit = 1000.0;  // glTF 2.0 lengths are metres
  std::vector<Eigen::Vector3d> V;
  std::vector<Eigen::Vector2d> UV;
  std::vector<std::array<std::uint8_t, 3>> colors;
  std::vector<Eigen::Vector3i> F;
  int texture_image = -1;
  bool has_uv = true, has_color = true;
  auto add_mesh = [&](int mesh_index, const Eigen::Matrix4d& M) {
    const auto& mesh = model.meshes.at(mesh_index);
    for (const auto& prim : mesh.primitives) {
      const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
      if (mode != TINYGLTF_MODE_TRIANGLES) {
        s.notes.push_back(cat("skipped a primitive of mesh '", mesh.name, "' that is not triangles"));
        continue;
      }
      const auto pos = prim.attributes.find("POSITION");
      if (pos == prim.attributes.end()) continue;
      const AccessorView P = view_of(model, pos->second, s.source);
      if (P.components < 3)
        throw InvalidInput(cat(s.source, ": the POSITION accessor ", pos->second, " has ",
                               P.components, " component(s) a vertex; a position needs 3 (VEC3)"));
      // Nodes may share a mesh (a scene graph is a DAG): bound what the instances add up to.
      if (V.size() + P.count > kMaxGltfVertices)
        throw InvalidInput(cat(s.source, ": the scene's mesh instances hold more than ",
                               kMaxGltfVertices, " vertices; export the scan as one mesh"));
      const int base = static_cast<int>(V.size());
      for (std::size_t i = 0; i < P.count; ++i)
        V.push_back((M * Eigen::Vector4d(P.get(i, 0), P.get(i, 1), P.get(i, 2), 1.0)).head<3>());
      const auto tc = prim.attributes.find("TEXCOORD_0");
      if (tc != prim.attributes.end()) {
        const AccessorView T = view_of(model, tc->second, s.source);
        for (std::size_t i = 0; i < P.count; ++i)
          UV.emplace_back(i < T.count ? T.get(i, 0) : 0.0, i < T.count ? T.get(i, 1) : 0.0);
      } else {
        has_uv = false;
      }
      const auto col = prim.attributes.find("COLOR_0");
      if (col != prim.attributes.end()) {
        const AccessorView C = view_of(model, col->second, s.source);
        const bool unit = C.type == TINYGLTF_COMPONENT_TYPE_FLOAT || C.normalized;
        for (std::size_t i = 0; i < P.count; ++i) {
          std::array<std::uint8_t, 3> c{};
          for (int k = 0; k < 3; ++k)
            c[k] = channel_byte(C.get(i, k) * (unit ? 255.0 : 1.0));
          colors.push_back(c);
        }
      } else {
        has_color = false;
      }
      if (prim.indices >= 0) {
        const AccessorView I = view_of(model, prim.indices, s.source);
        for (std::size_t i = 0; i + 2 < I.count; i += 3) {
          for (int k = 0; k < 3; ++k)
            if (!(I.get(i + k, 0) >= 0 && I.get(i + k, 0) < static_cast<double>(P.count)))
              throw InvalidInput(cat(s.source, ": index ", i + k, " of accessor ", prim.indices, " = ",
                                     I.get(i + k, 0), " names no vertex of its ", P.count));
          F.emplace_back(base + int(I.get(i, 0)), base + int(I.get(i + 1, 0)), base + int(I.get(i + 2, 0)));
        }
      } else {
        for (std::size_t i = 0; i + 2 < P.count; i += 3)
          F.emplace_back(base + int(i), base + int(i + 1), base + int(i + 2));
      }
      if (prim.material >= 0 && texture_image < 0) {
        const int t = model.materials.at(prim.material).pbrMetallicRoughness.baseColorTexture.index;
        if (t >= 0 && t < static_cast<int>(model.textures.size())) texture_image = model.textures[t].source;
      }
    }
  };
  // Walk the default scene's node tree (or every root if there is no scene).
  // A node that is its own ancestor would recurse without end, and a very deep chain would
  // overflow the stack: both are refused.
  constexpr int kMaxNodeDepth = 256;
  constexpr long kMaxNodeVisits = 1000000;
  long n_visits = 0;
  std::vector<char> on_path(model.nodes.size(), 0);
  std::function<void(int, const Eigen::Matrix4d&, int)> walk = [&](int n, const Eigen::Matrix4d& parent,
                                                                   int depth) {
    if (n < 0 || n >= static_cast<int>(model.nodes.size()))
      throw InvalidInput(cat(s.source, ": node ", n, " does not exist"));
    if (on_path[n])
      throw InvalidInput(cat(s.source, ": node ", n, " is its own ancestor (a cycle in the node "
                                       "tree); the file is damaged"));
    if (depth > kMaxNodeDepth)
      throw InvalidInput(cat(s.source, ": the node tree is more than ", kMaxNodeDepth,
                             " levels deep; the file is damaged"));
    if (++n_visits > kMaxNodeVisits)
      throw InvalidInput(cat(s.source, ": the node tree instances more than ", kMaxNodeVisits,
                             " nodes (shared subtrees); the file is damaged"));
    const auto& node = model.nodes[n];
    const Eigen::Matrix4d M = parent * node_matrix(node);
    if (node.mesh >= 0) {
      if (node.mesh >= static_cast<int>(model.meshes.size()))
        throw InvalidInput(cat(s.source, ": node ", n, " names mesh ", node.mesh,
                               ", which does not exist"));
      add_mesh(node.mesh, M);
    }
    on_path[n] = 1;
    for (int c : node.children) walk(c, M, depth + 1);
    on_path[n] = 0;
  };
  const int scene = model.defaultScene >= 0 ? model.defaultScene : 0;
  if (scene < static_cast<int>(model.scenes.size())) {
    for (int n : model.scenes[scene].nodes) walk(n, Eigen::Matrix4d::Identity(), 0);
  } else {
    for (std::size_t m = 0; m < model.meshes.size(); ++m) add_mesh(static_cast<int>(m), Eigen::Matrix4d::Identity());
  }
  s.mesh.V.resize(static_cast<Eigen::Index>(V.size()), 3);
  for (std::size_t i = 0; i < V.size(); ++i) s.mesh.V.row(i) = V[i].transpose();
  set_faces(s, F, s.mesh.n_vertices());
  if (has_uv && !UV.empty()) {
    s.UV.resize(static_cast<Eigen::Index>(UV.size()), 2);
    for (std::size_t i = 0; i < UV.size(); ++i) s.UV.row(i) = UV[i].transpose();
    s.FUV = s.mesh.F;  // glTF texture coordinates are per vertex
  }
  if (has_color && !colors.empty()) {
    s.vertex_colors.resize(static_cast<Eigen::Index>(colors.size()), 3);
    for (std::size_t i = 0; i < colors.size(); ++i)
      for (int k = 0; k < 3; ++k) s.vertex_colors(i, k) = colors[i][k];
  }
  if (o.texture.empty() && texture_image >= 0) {
    s.texture = to_rgb(model.images.at(texture_image), s.source);
    s.texture_source = cat(s.source, " (base colour texture)");
  }
  finish(s, o);
  return s;
}

// ---- VTK legacy polydata (ASCII)
ScanMesh read_vtk(const fs::path& path, const ScanReadOptions& o) {
  ScanMesh s;
  std::ifstream in = open_scan(path, "VTK", s);
  std::string line;
  std::getline(in, line);
  if (line.rfind("# vtk DataFile", 0) != 0)
    throw InvalidInput(cat(s.source, ": not a VTK legacy file (no '# vtk DataFile' header)"));
  std::getline(in, line);  // title
  std::string encoding;
  in >> encoding;
  if (encoding != "ASCII")
    throw InvalidInput(cat(s.source, ": ", encoding, " VTK files are not supported; save as ASCII"));
  std::string word;
  std::vector<Eigen::Vector3i> F;
  Eigen::Index n_points = 0;
  bool in_point_data = false;
  auto need = [&](bool ok, const char* what) {
    if (!ok) throw IoError(cat(s.source, ": truncated or malformed while reading ", what));
  };
  // Every ASCII value takes at least two bytes (a digit and a separator): a declared count that
  // the rest of the file cannot hold is refused before anything is allocated for it.
  std::error_code size_ec;
  const auto file_bytes = static_cast<double>(fs::file_size(path, size_ec));
  auto fits = [&](double n_values, const std::string& what) {
    const double rest = file_bytes - static_cast<double>(std::max<std::streamoff>(in.tellg(), 0));
    if (!(n_values >= 0) || 2.0 * n_values > rest + 2.0)
      throw IoError(cat(s.source, ": ", what, " declares ", n_values, " values but only ", rest,
                        " bytes follow; the file is truncated or the count is wrong"));
  };
  while (in >> word) {
    if (word == "DATASET") {
      in >> word;
      if (word != "POLYDATA")
        throw InvalidInput(cat(s.source, ": dataset ", word, " is not POLYDATA (a surface)"));
    } else if (word == "POINTS") {
      std::string type;
      need(static_cast<bool>(in >> n_points >> type), "POINTS");
      fits(3.0 * static_cast<double>(n_points), "POINTS");
      s.mesh.V.resize(n_points, 3);
      for (Eigen::Index i = 0; i < n_points; ++i)
        for (int c = 0; c < 3; ++c) {
          std::string v;
          need(static_cast<bool>(in >> v), "POINTS");
          s.mesh.V(i, c) = std::strtod(v.c_str(), nullptr);
          if (v == "nan" || v == "NaN" || v == "-nan") s.mesh.V(i, c) = std::nan("");
        }
    } else if (word == "POLYGONS" || word == "TRIANGLE_STRIPS") {
      long n = 0, size = 0;
      need(static_cast<bool>(in >> n >> size), word.c_str());
      fits(static_cast<double>(n), word);
      fits(static_cast<double>(size), word);
      for (long c = 0; c < n; ++c) {
        int k = 0;
        need(static_cast<bool>(in >> k), word.c_str());
        fits(static_cast<double>(k), word);
        std::vector<int> ids(k);
        for (int& id : ids) need(static_cast<bool>(in >> id), word.c_str());
        if (word == "POLYGONS") {
          for (int t = 1; t + 1 < k; ++t) F.emplace_back(ids[0], ids[t], ids[t + 1]);
        } else {
          for (int t = 0; t + 2 < k; ++t)
            F.push_back(t % 2 ? Eigen::Vector3i(ids[t + 1], ids[t], ids[t + 2])
                              : Eigen::Vector3i(ids[t], ids[t + 1], ids[t + 2]));
        }
      }
    } else if (word == "VERTICES" || word == "LINES") {
      long n = 0, size = 0;
      need(static_cast<bool>(in >> n >> size), word.c_str());
      for (long i = 0; i < size; ++i) need(static_cast<bool>(in >> word), "cells");
    } else if (word == "POINT_DATA") {
      in >> word;
      in_point_data = true;
    } else if (word == "CELL_DATA") {
      in >> word;
      in_point_data = false;
    } else if (word == "TEXTURE_COORDINATES" && in_point_data) {
      std::string name, type;
      int dim = 0;
      need(static_cast<bool>(in >> name >> dim >> type), "TEXTURE_COORDINATES");
      fits(2.0 * static_cast<double>(n_points), "TEXTURE_COORDINATES");
      s.UV.resize(n_points, 2);
      for (Eigen::Index i = 0; i < n_points; ++i)
        for (int c = 0; c < dim; ++c) {
          double v;
          need(static_cast<bool>(in >> v), "TEXTURE_COORDINATES");
          if (c < 2) s.UV(i, c) = c == 1 ? 1.0 - v : v;  // VTK's v points up
        }
    }
  }
  set_faces(s, F, n_points, "a polygon refers to a point");
  if (s.UV.rows() > 0) s.FUV = s.mesh.F;
  finish(s, o);
  return s;
}

// ---- Wavefront OBJ with MTL
ScanMesh read_obj(const fs::path& path, const ScanReadOptions& o) {
  ScanMesh s;
  std::ifstream in = open_scan(path, "OBJ", s);
  std::vector<Eigen::Vector3d> V;
  std::vector<Eigen::Vector2d> T;
  std::vector<Eigen::Vector3i> F, FT;
  std::vector<std::array<std::uint8_t, 3>> colors;
  std::string mtllib, line;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string tag;
    ls >> tag;
    if (tag == "v") {
      Eigen::Vector3d p;
      std::string x, y, z;
      ls >> x >> y >> z;
      p = {std::strtod(x.c_str(), nullptr), std::strtod(y.c_str(), nullptr), std::strtod(z.c_str(), nullptr)};
      V.push_back(p);
      double r, g, b;
      if (ls >> r >> g >> b)
        colors.push_back({channel_byte(r * 255), channel_byte(g * 255), channel_byte(b * 255)});
    } else if (tag == "vt") {
      double u = 0, v = 0;
      ls >> u >> v;
      T.emplace_back(u, 1.0 - v);  // OBJ's v points up
    } else if (tag == "f") {
      std::vector<int> vi, ti;
      std::string c;
      while (ls >> c) {
        const int a = std::atoi(c.c_str());
        vi.push_back(a < 0 ? static_cast<int>(V.size()) + a : a - 1);
        const auto slash = c.find('/');
        int t = -1;
        if (slash != std::string::npos && slash + 1 < c.size() && c[slash + 1] != '/') {
          const int b = std::atoi(c.c_str() + slash + 1);
          t = b < 0 ? static_cast<int>(T.size()) + b : b - 1;
        }
        ti.push_back(t);
      }
      for (std::size_t k = 1; k + 1 < vi.size(); ++k) {
        F.emplace_back(vi[0], vi[k], vi[k + 1]);
        FT.emplace_back(ti[0], ti[k], ti[k + 1]);
      }
    } else if (tag == "mtllib") {
      std::getline(ls >> std::ws, mtllib);
    }
  }
  s.mesh.V.resize(static_cast<Eigen::Index>(V.size()), 3);
  for (std::size_t i = 0; i < V.size(); ++i) s.mesh.V.row(i) = V[i].transpose();
  set_faces(s, F, s.mesh.n_vertices());
  bool all_uv = !T.empty() && !FT.empty();
  for (const auto& ft : FT) all_uv = all_uv && ft.minCoeff() >= 0;
  if (all_uv) {
    s.UV.resize(static_cast<Eigen::Index>(T.size()), 2);
    for (std::size_t i = 0; i < T.size(); ++i) s.UV.row(i) = T[i].transpose();
    s.FUV.resize(static_cast<Eigen::Index>(FT.size()), 3);
    for (std::size_t i = 0; i < FT.size(); ++i) s.FUV.row(i) = FT[i].transpose();
  }
  if (colors.size() == V.size() && !V.empty()) {
    s.vertex_colors.resize(static_cast<Eigen::Index>(V.size()), 3);
    for (std::size_t i = 0; i < V.size(); ++i)
      for (int k = 0; k < 3; ++k) s.vertex_colors(i, k) = colors[i][k];
  }
  if (o.texture.empty() && !mtllib.empty()) {
    const fs::path mtl = path.parent_path() / mtllib;
    std::ifstream m(mtl);
    if (!m) throw IoError(cat(s.source, ": its material file ", mtl.string(), " is missing; give "
                                         "the texture with --texture"));
    while (std::getline(m, line)) {
      std::istringstream ls(line);
      std::string tag;
      ls >> tag;
      if (tag == "map_Kd") {
        std::string rest;
        std::getline(ls >> std::ws, rest);
        // Options such as -s u v come first; the file name is the last word.
        const auto sp = rest.find_last_of(' ');
        const fs::path tex = mtl.parent_path() / (sp == std::string::npos ? rest : rest.substr(sp + 1));
        s.texture = read_image(tex);
        s.texture_source = tex.string();
        break;
      }
    }
  }
  finish(s, o);
  return s;
}

// ---- PLY with vertex colours and optional texture coordinates (the volume module's reader).
ScanMesh read_ply_scan(const fs::path& path, const ScanReadOptions& o) {
  ScanMesh s;
  s.source = path.string();
  s.format = "PLY";
  PlyMesh ply = read_ply_with_attributes(path);
  s.mesh = std::move(ply.mesh);
  s.vertex_colors = std::move(ply.colors);
  if (ply.uv.rows() > 0) {
    s.UV = std::move(ply.uv);
    s.UV.col(1) = (1.0 - s.UV.col(1).array()).matrix();  // PLY's v points up
    s.FUV = s.mesh.F;
  }
  finish(s, o);
  return s;
}

}  // namespace

ScanMesh read_scan_mesh(const fs::path& path, const ScanReadOptions& options) {
  require_readable(path, false, "check the path and its permissions");
  const std::string ext = lower(path.extension().string());
  // Errors of the libraries underneath (tinygltf's containers, allocation) are the file's fault.
  try {
    if (ext == ".glb" || ext == ".gltf") return read_gltf(path, options);
    if (ext == ".vtk") return read_vtk(path, options);
    if (ext == ".obj") return read_obj(path, options);
    if (ext == ".ply") return read_ply_scan(path, options);
  } catch (const std::bad_alloc&) {
    throw IoError(cat(path.string(), ": not enough memory to read it; its counts are probably "
                                     "damaged"));
  } catch (const std::logic_error& e) {  // out_of_range, length_error, invalid_argument
    throw InvalidInput(cat(path.string(), ": damaged or inconsistent (", e.what(), ")"));
  }
  throw InvalidInput(cat(path.string(), ": unknown scan format '", ext, "'; use .glb, .gltf, .ply, "
                                        ".obj or .vtk"));
}

}  // namespace caps

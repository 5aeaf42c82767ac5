#include "caps/volume/mesh_io.hpp"

#include "caps/core/atomic_output.hpp"
#include "caps/core/checked_numbers.hpp"
#include "caps/core/error.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

namespace caps {
namespace {

// ---------------------------------------------------------------------------------------------
// Writing.

template <typename T>
void put_le(std::string& buf, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(bytes, bytes + sizeof(T));
  buf.append(bytes, sizeof(T));
}

// ---------------------------------------------------------------------------------------------
// Reading.

enum class Scalar { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

bool parse_scalar(std::string_view name, Scalar& s) {
  static const std::pair<std::string_view, Scalar> kNames[] = {
      {"char", Scalar::Int8},      {"int8", Scalar::Int8},       {"uchar", Scalar::UInt8},
      {"uint8", Scalar::UInt8},    {"short", Scalar::Int16},     {"int16", Scalar::Int16},
      {"ushort", Scalar::UInt16},  {"uint16", Scalar::UInt16},   {"int", Scalar::Int32},
      {"int32", Scalar::Int32},    {"uint", Scalar::UInt32},     {"uint32", Scalar::UInt32},
      {"float", Scalar::Float32},  {"float32", Scalar::Float32}, {"double", Scalar::Float64},
      {"float64", Scalar::Float64}};
  for (const auto& [n, v] : kNames)
    if (n == name) {
      s = v;
      return true;
    }
  return false;
}

struct Property {
  std::string name;
  Scalar type = Scalar::Float32;
  bool is_list = false;
  Scalar count_type = Scalar::UInt8;
};

struct Element {
  std::string name;
  std::int64_t count = 0;
  std::vector<Property> props;
};

enum class Format { Ascii, BinaryLE, BinaryBE };

// The role of a scalar vertex property by its name (the names scanners and MeshLab write):
// 0..2 x y z, 3..5 red green blue, 6..7 texture u v, -1 anything else.
int vertex_role(const std::string& name) {
  static const std::pair<std::string_view, int> kNames[] = {
      {"x", 0},     {"y", 1},         {"z", 2},         {"red", 3},       {"r", 3},
      {"green", 4}, {"g", 4},         {"blue", 5},      {"b", 5},         {"u", 6},
      {"s", 6},     {"texture_u", 6}, {"v", 7},         {"t", 7},         {"texture_v", 7}};
  for (const auto& [n, role] : kNames)
    if (n == name) return role;
  return -1;
}

// Reads values one after the other from the body, in whichever encoding the header declared.
class BodyReader {
 public:
  BodyReader(const std::string& file, std::size_t pos, Format fmt, const std::string& name)
      : s_(file), pos_(pos), fmt_(fmt), name_(name) {}

  double next(Scalar t) { return fmt_ == Format::Ascii ? next_ascii() : next_binary(t); }
  std::size_t remaining() const { return s_.size() - pos_; }

 private:
  template <typename T>
  double read_bin() {
    if (s_.size() - pos_ < sizeof(T)) truncated();
    char bytes[sizeof(T)];
    std::memcpy(bytes, s_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    const bool file_big = fmt_ == Format::BinaryBE;
    if (file_big != (std::endian::native == std::endian::big))
      std::reverse(bytes, bytes + sizeof(T));
    T v;
    std::memcpy(&v, bytes, sizeof(T));
    return static_cast<double>(v);
  }
  double next_binary(Scalar t) {
    switch (t) {
      case Scalar::Int8:
        return read_bin<std::int8_t>();
      case Scalar::UInt8:
        return read_bin<std::uint8_t>();
      case Scalar::Int16:
        return read_bin<std::int16_t>();
      case Scalar::UInt16:
        return read_bin<std::uint16_t>();
      case Scalar::Int32:
        return read_bin<std::int32_t>();
      case Scalar::UInt32:
        return read_bin<std::uint32_t>();
      case Scalar::Float32:
        return read_bin<float>();
      case Scalar::Float64:
        return read_bin<double>();
    }
    return 0.0;
  }
  double next_ascii() {
    while (pos_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[pos_]))) ++pos_;
    if (pos_ >= s_.size()) truncated();
    std::size_t end = pos_;
    while (end < s_.size() && !std::isspace(static_cast<unsigned char>(s_[end]))) ++end;
    const std::string token = s_.substr(pos_, end - pos_);
    pos_ = end;
    // strtod also accepts "nan" and "inf", which are then rejected with a precise message.
    char* stop = nullptr;
    const double v = std::strtod(token.c_str(), &stop);
    if (stop != token.c_str() + token.size())
      throw InvalidInput(cat(name_, ": PLY value '", token, "' is not a number"));
    return v;
  }
  [[noreturn]] void truncated() const {
    throw IoError(cat(name_, ": PLY file is truncated (data ends after ", s_.size(),
                      " bytes before all declared elements were read); re-export or re-copy it"));
  }

  const std::string& s_;  // not owned; the file contents outlive the reader
  std::size_t pos_;
  Format fmt_;
  const std::string& name_;  // not owned
};

}  // namespace

void write_ply(const TriMesh& mesh, const std::filesystem::path& path,
               const Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 3>* colors) {
  write_ply(mesh, path, colors, nullptr);
}

void write_ply(const TriMesh& mesh, const std::filesystem::path& path,
               const Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 3>* colors,
               const PlyScalar* scalar) {
  const Eigen::Index nv = mesh.n_vertices(), nf = mesh.n_faces();
  const std::string name = path.string();
  if (nf > 0 && (mesh.F.minCoeff() < 0 || mesh.F.maxCoeff() >= nv))
    throw InvalidInput(cat(name, ": cannot write PLY, face indices span [", mesh.F.minCoeff(), ", ",
                           mesh.F.maxCoeff(), "] but the mesh has ", nv, " vertices"));
  if (!mesh.V.allFinite())
    throw InvalidInput(cat(name, ": cannot write PLY, the mesh has non-finite vertex coordinates"));
  if (colors && colors->rows() != nv)
    throw InvalidInput(
        cat(name, ": cannot write PLY, ", colors->rows(), " colours for ", nv, " vertices"));
  if (scalar && (scalar->values.size() != nv || scalar->name.empty() ||
                 scalar->name.find_first_of(" \t\n") != std::string::npos))
    throw InvalidInput(cat(name, ": cannot write PLY, the vertex property '", scalar ? scalar->name : "",
                           "' needs a name without spaces and ", nv, " values"));

  std::string buf;
  buf.reserve(256 + std::size_t(nv) * (colors ? 15 : 12) + std::size_t(nf) * 13);
  buf += "ply\nformat binary_little_endian 1.0\ncomment caps: units mm, frame LPS\n";
  buf += cat("element vertex ", nv, "\nproperty float x\nproperty float y\nproperty float z\n");
  if (colors) buf += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  if (scalar) buf += cat("property float ", scalar->name, "\n");
  buf += cat("element face ", nf, "\nproperty list uchar int vertex_indices\nend_header\n");
  for (Eigen::Index v = 0; v < nv; ++v) {
    for (int c = 0; c < 3; ++c) put_le(buf, static_cast<float>(mesh.V(v, c)));
    if (colors)
      for (int c = 0; c < 3; ++c) buf.push_back(static_cast<char>((*colors)(v, c)));
    if (scalar) put_le(buf, static_cast<float>(scalar->values[v]));
  }
  for (Eigen::Index f = 0; f < nf; ++f) {
    buf.push_back(3);
    for (int c = 0; c < 3; ++c) put_le(buf, static_cast<std::int32_t>(mesh.F(f, c)));
  }
  write_file_atomic(path, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
    out.close();
    if (!out) throw IoError(cat(name, ": writing the PLY file failed (disk full?)"));
  });
}

void write_ply(const TriMesh& mesh, const std::filesystem::path& path) {
  write_ply(mesh, path, nullptr);
}

TriMesh read_ply(const std::filesystem::path& path) { return read_ply_with_attributes(path).mesh; }

PlyMesh read_ply_with_attributes(const std::filesystem::path& path) {
  const std::string name = path.string();
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(cat(name, ": cannot open the PLY file; check the path and permissions"));
  std::string file((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw IoError(cat(name, ": reading the PLY file failed"));

  // Header: lines up to "end_header".
  std::size_t pos = 0;
  auto next_line = [&](std::string& line) {
    if (pos >= file.size()) return false;
    std::size_t e = file.find('\n', pos);
    if (e == std::string::npos)
      throw IoError(
          cat(name, ": PLY header is cut off before 'end_header'; the file is truncated"));
    line = file.substr(pos, e - pos);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    pos = std::min(e + 1, file.size() + 1);
    return true;
  };
  std::string line;
  if (!next_line(line) || line != "ply")
    throw InvalidInput(cat(name, ": not a PLY file (the first line must be 'ply')"));
  Format fmt = Format::Ascii;
  bool have_format = false, have_end = false;
  std::vector<Element> elements;
  int line_no = 1;
  while (next_line(line)) {
    ++line_no;
    std::istringstream ls(line);
    std::string kw;
    ls >> kw;
    auto bad = [&](const std::string& why) {
      return InvalidInput(cat(name, ": PLY header line ", line_no, " '", line, "': ", why));
    };
    if (kw.empty() || kw == "comment" || kw == "obj_info") continue;
    if (kw == "end_header") {
      have_end = true;
      break;
    }
    if (kw == "format") {
      std::string f;
      ls >> f;
      if (f == "ascii")
        fmt = Format::Ascii;
      else if (f == "binary_little_endian")
        fmt = Format::BinaryLE;
      else if (f == "binary_big_endian")
        fmt = Format::BinaryBE;
      else
        throw bad("unknown format");
      have_format = true;
    } else if (kw == "element") {
      Element el;
      if (!(ls >> el.name >> el.count) || el.count < 0)
        throw bad("expected 'element <name> <count>'");
      elements.push_back(std::move(el));
    } else if (kw == "property") {
      if (elements.empty()) throw bad("property before any element");
      Property p;
      std::string t;
      ls >> t;
      if (t == "list") {
        std::string ct, it;
        ls >> ct >> it >> p.name;
        p.is_list = true;
        if (!parse_scalar(ct, p.count_type) || !parse_scalar(it, p.type) || p.name.empty())
          throw bad("expected 'property list <count type> <item type> <name>'");
      } else {
        ls >> p.name;
        if (!parse_scalar(t, p.type) || p.name.empty())
          throw bad("expected 'property <type> <name>'");
      }
      elements.back().props.push_back(std::move(p));
    } else {
      throw bad("unknown keyword");
    }
  }
  if (!have_end)
    throw IoError(cat(name, ": PLY header has no 'end_header'; the file is truncated or not PLY"));
  if (!have_format) throw InvalidInput(cat(name, ": PLY header has no 'format' line"));

  PlyMesh out;
  TriMesh& mesh = out.mesh;
  bool have_vertices = false, have_faces = false, have_colors = false, have_uv = false;
  BodyReader body(file, std::min(pos, file.size()), fmt, name);
  std::vector<int> poly;
  std::vector<std::array<int, 3>> tris;
  for (const Element& el : elements) {
    const bool is_vertex = el.name == "vertex", is_face = el.name == "face";
    int ix = -1, iy = -1, iz = -1, ifl = -1;
    // What each scalar vertex property is: 0..2 the coordinates, 3..5 the colour, 6..7 the
    // texture coordinates, -1 skipped.
    std::vector<int> role(el.props.size(), -1);
    for (int q = 0; q < int(el.props.size()); ++q) {
      const Property& p = el.props[q];
      if (is_vertex && !p.is_list) role[q] = vertex_role(p.name);
      if (is_face && p.is_list && (p.name == "vertex_indices" || p.name == "vertex_index")) ifl = q;
      if (role[q] == 0) ix = q;
      if (role[q] == 1) iy = q;
      if (role[q] == 2) iz = q;
      if (role[q] == 3) have_colors = true;
      if (role[q] == 6) have_uv = true;
    }
    if (is_vertex && (ix < 0 || iy < 0 || iz < 0))
      throw InvalidInput(cat(name, ": PLY vertex element lacks x, y or z"));
    if (is_face && ifl < 0)
      throw InvalidInput(cat(name, ": PLY face element lacks a vertex_indices list"));
    // An element without properties holds no data whatever its count (fuzz_ply: a count of
    // 4e17 looped for ever over nothing). Any other needs one byte an item at the least (the
    // least any encoding takes): a count beyond the bytes left is a lie, refused before the
    // vertices or faces are allocated.
    if (el.props.empty()) continue;
    if (std::size_t(el.count) > body.remaining())
      throw IoError(cat(name, ": PLY declares ", el.count, " '", el.name, "' elements but only ",
                        body.remaining(), " bytes follow; the file is truncated"));
    if (is_vertex) {
      mesh.V.resize(el.count, 3);
      if (have_colors) out.colors.setZero(el.count, 3);
      if (have_uv) out.uv.setZero(el.count, 2);
      have_vertices = true;
    }
    if (is_face) {
      tris.reserve(tris.size() + std::size_t(el.count));
      have_faces = true;
    }
    for (std::int64_t n = 0; n < el.count; ++n) {
      for (int q = 0; q < int(el.props.size()); ++q) {
        const Property& p = el.props[q];
        if (!p.is_list) {
          const double v = body.next(p.type);
          if (!is_vertex || role[q] < 0) continue;
          if (role[q] <= 2) {
            if (!std::isfinite(v))
              throw InvalidInput(cat(name, ": PLY vertex ", n, " has a non-finite coordinate (", v,
                                     "); repair the mesh in the program that wrote it"));
            mesh.V(n, role[q]) = v;
          } else if (role[q] <= 5 && have_colors) {
            const bool unit = p.type == Scalar::Float32 || p.type == Scalar::Float64;
            out.colors(n, role[q] - 3) =
                channel_byte(v * (unit ? 255.0 : 1.0));
          } else if (role[q] >= 6 && have_uv) {
            out.uv(n, role[q] - 6) = v;
          }
          continue;
        }
        const double cnt = body.next(p.count_type);
        if (!(cnt >= 0) || cnt > 1e6 || cnt > double(body.remaining()))
          throw InvalidInput(cat(name, ": PLY ", el.name, " ", n, " has a list of ", cnt,
                                 " items, more than the ", body.remaining(),
                                 " bytes left in the file"));
        const int m = int(cnt);
        if (is_face && q == ifl) poly.clear();
        for (int c = 0; c < m; ++c) {
          const double v = body.next(p.type);
          if (is_face && q == ifl) {
            if (!(v >= 0 && v < double(mesh.n_vertices())) || v != std::floor(v))
              throw InvalidInput(cat(name, ": PLY face ", n, " refers to vertex ", v,
                                     " but there are ", mesh.n_vertices(),
                                     " vertices (indices start at 0)"));
            poly.push_back(int(v));
          }
        }
        if (is_face && q == ifl) {
          if (m < 3)
            throw InvalidInput(cat(name, ": PLY face ", n, " has ", m, " vertices; need >= 3"));
          for (int c = 1; c + 1 < m; ++c) tris.push_back({poly[0], poly[c], poly[c + 1]});
        }
      }
    }
  }
  if (!have_vertices) throw InvalidInput(cat(name, ": PLY file has no vertex element"));
  if (!have_faces || tris.empty())
    throw InvalidInput(cat(name,
                           ": PLY file has no faces (a point cloud?); caps needs a "
                           "triangle surface"));
  mesh.F.resize(Eigen::Index(tris.size()), 3);
  for (std::size_t f = 0; f < tris.size(); ++f)
    for (int c = 0; c < 3; ++c) mesh.F(Eigen::Index(f), c) = tris[f][c];
  return out;
}

}  // namespace caps

#pragma once
/// @brief Reading and writing triangle meshes as PLY (Stanford polygon files).
///
/// Written files are binary little-endian with the standard property names (x y z, red green blue,
/// vertex_indices), which ParaView, 3D Slicer, MeshLab and Blender open. Coordinates are LPS mm;
/// a header comment says so. Note that 3D Slicer assumes LPS for PLY unless told otherwise.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <string>

#include "caps/core/mesh.hpp"

namespace caps {

/// Writes a mesh as binary little-endian PLY, atomically (temporary file, then rename).
/// Header: "comment caps: units mm, frame LPS"; vertex x y z as float, face list uchar int.
/// @param mesh    V #V×3 (LPS, mm), F #F×3
/// @param path    output file; its directory must exist
/// @param colors  optional #V×3 per-vertex RGB (written as uchar red green blue); not owned
/// Throws InvalidInput for bad indices or non-finite vertices, IoError if the file cannot be
/// written.
void write_ply(const TriMesh& mesh, const std::filesystem::path& path,
               const Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 3>* colors);

/// A named per-vertex value written as a PLY float property after x y z (and the colours).
struct PlyScalar {
  std::string name;        ///< the property's name, no spaces (e.g. "distance")
  Eigen::VectorXd values;  ///< #V values
};

/// write_ply() with colours (or nullptr) and one scalar vertex property (or nullptr); throws
/// InvalidInput also for a scalar whose size is not #V or whose name is empty or has spaces.
void write_ply(const TriMesh& mesh, const std::filesystem::path& path,
               const Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 3>* colors,
               const PlyScalar* scalar);

/// Writes a mesh as binary little-endian PLY without colours; see the overload above.
void write_ply(const TriMesh& mesh, const std::filesystem::path& path);

/// A PLY mesh with the per-vertex attributes scanners write.
struct PlyMesh {
  TriMesh mesh;  ///< V #V×3 as stored, F #F×3
  /// #V×3 colours (red green blue or r g b; float values in [0, 1] scaled to 0..255), or empty.
  Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 3> colors;
  /// #V×2 texture coordinates as stored (u, v; s t or texture_u texture_v; PLY's v points up),
  /// or empty.
  Eigen::MatrixX2d uv;
};

/// Reads a PLY file: ascii, binary_little_endian or binary_big_endian; vertex x y z of any
/// numeric type, with colours and texture coordinates if present; faces as a vertex_indices (or
/// vertex_index) list, polygons split into fans of triangles. Other elements and properties are
/// skipped.
/// @param path  the file
/// Throws IoError if the file is missing, unreadable or truncated; InvalidInput (naming the file)
/// for a malformed header, no vertex coordinates, no faces, non-finite coordinates, a face with
/// fewer than 3 vertices or an index out of range.
PlyMesh read_ply_with_attributes(const std::filesystem::path& path);

/// read_ply_with_attributes() without the attributes.
/// @return  V #V×3 as stored (caps writes LPS mm), F #F×3
TriMesh read_ply(const std::filesystem::path& path);

}  // namespace caps

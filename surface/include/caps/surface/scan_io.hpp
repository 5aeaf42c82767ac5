#pragma once
/// @brief Reading textured surface scans: glTF 2.0 (.gltf/.glb), PLY with vertex colours, OBJ
/// with MTL and texture, VTK legacy polydata with texture coordinates; JPEG and PNG textures
/// (read_image(), caps::image).
///
/// Meshes are returned as stored: file units, file frame. Texture coordinates are normalised to
/// image convention on reading (u to the right, v downward: row = v * height), so OBJ and VTK
/// (v upward) are flipped and glTF (already v downward) is not; ScanReadOptions::flip_v flips
/// once more for files that break their format's convention.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "caps/core/mesh.hpp"
#include "caps/image/image_io.hpp"

namespace caps {

/// A surface scan as read from a file.
struct ScanMesh {
  TriMesh mesh;                 ///< V #V×3 (file units and frame), F #F×3
  Eigen::MatrixX2d UV;          ///< texture coordinates, image convention (see @brief)
  Eigen::MatrixX3i FUV;         ///< #F×3 rows of UV per face corner; empty without UVs
  Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 3> vertex_colors;  ///< #V×3 or empty
  RgbImage texture;             ///< empty without a texture
  std::string texture_source;   ///< where the texture came from
  std::string source;           ///< the file
  std::string format;           ///< "glTF", "PLY", "OBJ", "VTK"
  double mm_per_unit = 0;       ///< from the format (glTF: 1000, metres); 0 if it does not say
  std::vector<std::string> notes;
};

struct ScanReadOptions {
  std::filesystem::path texture;  ///< a texture image (JPEG or PNG) overriding the file's own
  bool flip_v = false;            ///< v' = 1 - v after the format's own convention
};

/// Reads a scan by its extension (.glb, .gltf, .ply, .obj, .vtk). Throws IoError for a missing,
/// unreadable or truncated file or texture; InvalidInput for malformed content, no faces,
/// indices out of range or non-finite coordinates.
ScanMesh read_scan_mesh(const std::filesystem::path& path, const ScanReadOptions& options = {});

}  // namespace caps

#pragma once
/// @brief The mesh directory (format caps-mesh version 1, docs/mesh-format.md):
/// mesh.vtu (VTK XML UnstructuredGrid, ascii; point data "fixed", "suture_partner", cell data
/// "layer") and mesh.json (units, counts, materials, fixed nodes/dofs, loads, sutures, refs).

#include <filesystem>

#include "caps/fem/mesh.hpp"

namespace caps::fem {

/// Writes mesh.vtu and mesh.json into an existing directory `dir` (each file atomically).
void write_mesh_dir(const Mesh& mesh, const std::filesystem::path& dir);

/// Reads and validates a mesh directory. Throws IoError (missing/unreadable files) or
/// InvalidInput (bad content), naming the file and the offending item.
Mesh read_mesh_dir(const std::filesystem::path& dir);

}  // namespace caps::fem

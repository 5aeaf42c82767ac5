#pragma once
/// @brief Pictures of the meshes (PNG, drawn on a Canvas): the surface mesh like the paper's
/// Figure 3 and a cross-section of the continuum mesh like its Figure 4.

#include <filesystem>
#include <string>

#include "caps/mesher/continuum_mesher.hpp"
#include "caps/mesher/surface_mesher.hpp"

namespace caps::mesher {

/// The surface mesh in the local plane (arc mm across, z mm up), whole on the left and around the
/// wound on the right: the wound border in bold, stage-1 triangles shaded orange, polygons of
/// expanded vertices shaded blue, other triangles (edge splits) shaded grey. Written atomically.
void write_surface_mesh_png(const std::filesystem::path& path, const SurfaceMesh& surface,
                            const std::string& title);

/// A cross-section of the continuum mesh along z = z_c (through the wound's centre): the skin drawn
/// flat on top, the bone below at the local thickness, layer interfaces and the walls of the
/// elements the section cuts, depth exaggerated `depth_scale` times; gaps are the wound. Thickness and layers as in `options`. Written atomically.
void write_cross_section_png(const std::filesystem::path& path, const SurfaceMesh& surface,
                             const PatientModel& model, const ContinuumMeshOptions& options,
                             const std::string& title, double depth_scale = 3.0);

}  // namespace caps::mesher

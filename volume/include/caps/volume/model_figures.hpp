#pragma once
/// @brief The model directory's pictures (PNG): maps over (theta, z) unwrapped with theta across
/// (-180 .. 180, the face in the middle) and superior at the top, with theta and z axes.

#include <filesystem>
#include <cstdint>
#include <string>
#include <vector>

#include "caps/image/rgb_image.hpp"
#include "caps/volume/cylindrical_map.hpp"

namespace caps {

/// The thickness figure: the unwrapped map, a colour bar (viridis) with ticks in mm, axis labels,
/// and invalid cells hatched in grey. Written atomically.
/// @param values  grid.size() thicknesses (mm), theta fastest
void write_thickness_png(const std::filesystem::path& path, const CylindricalMaps& maps,
                         const std::vector<float>& values, const std::string& title,
                         const std::string& credit = "");

/// A tissue layer's figure, like write_thickness_png() but with the cells whose `layer_flags`
/// (LayerFlag) are set hatched, and `what` naming the layer on the colour bar ("fat (mm)").
void write_layer_png(const std::filesystem::path& path, const CylindricalMaps& maps,
                     const std::vector<float>& values, const std::vector<std::uint8_t>& layer_flags,
                     const std::string& what, const std::string& title,
                     const std::string& credit = "");

/// A shaded relief of the skin range image (like a Cyberware colour image), skin-toned. Written
/// atomically.
void write_skin_png(const std::filesystem::path& path, const CylindricalMaps& maps,
                    const std::string& title, const std::string& credit = "");

/// Any picture over the grid (e.g. a model's color.png), enlarged, with theta and z axes, a title
/// and a credit line (may be empty). Written atomically.
/// @param cells  n_theta × n_z pixels, superior (the last grid row) on top; else InvalidInput
void write_map_png(const std::filesystem::path& path, const CylinderGrid& grid,
                   const RgbImage& cells, const std::string& title, const std::string& credit = "");

}  // namespace caps

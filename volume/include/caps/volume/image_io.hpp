#pragma once
/// @brief 2-D image output: NRRD float maps over (theta, z) and PNG figures.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "caps/volume/cylindrical_map.hpp"

namespace caps {

/// Writes a float32 map over the cylinder grid as a detached-header-free NRRD (raw, little
/// endian), with spacings, axis mins, units (deg, mm) and labels (theta, z), atomically.
void write_map_nrrd(const std::filesystem::path& path, const std::vector<float>& values,
                    const CylinderGrid& grid, const std::string& content, const std::string& unit);

/// Reads a map written by write_map_nrrd(); checks its sizes against `grid`.
std::vector<float> read_map_nrrd(const std::filesystem::path& path, const CylinderGrid& grid);

/// An 8-bit RGB image, rows top to bottom.
struct RgbImage {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;  ///< width*height*3
};

/// Reads a PNG (any colour type) into RGB. Throws IoError.
RgbImage read_png(const std::filesystem::path& path);

/// Writes an 8-bit RGB PNG atomically. Throws InvalidInput if the buffer does not match the
/// size, IoError if it cannot be written.
void write_png(const std::filesystem::path& path, const RgbImage& image);

/// Perceptually uniform colour map (viridis), t in [0, 1].
Eigen::Vector3d viridis(double t);

/// The thickness figure: the unwrapped map (theta across, superior at the top), a colour bar
/// with ticks in mm, axis labels, and invalid cells hatched in grey. Written atomically.
void write_thickness_png(const std::filesystem::path& path, const CylindricalMaps& maps,
                         const std::vector<float>& values, const std::string& title,
                         const std::string& credit = "");

/// A shaded relief of the skin range image (like a Cyberware colour image), skin-toned,
/// superior at the top, theta = 0 (the face) in the middle. Written atomically.
void write_skin_png(const std::filesystem::path& path, const CylindricalMaps& maps,
                    const std::string& title, const std::string& credit = "");

}  // namespace caps

#pragma once
/// @brief The model's maps over (theta, z) as float32 NRRD files.

#include <filesystem>
#include <string>
#include <vector>

#include "caps/volume/cylindrical_map.hpp"

namespace caps {

/// Writes a float32 map over the cylinder grid as a detached-header-free NRRD (raw, little
/// endian), with spacings, axis mins, units (deg, mm) and labels (theta, z), atomically.
/// @param values  grid.size() values, theta fastest
void write_map_nrrd(const std::filesystem::path& path, const std::vector<float>& values,
                    const CylinderGrid& grid, const std::string& content, const std::string& unit);

/// Reads a map written by write_map_nrrd(); checks its sizes against `grid`. Throws IoError
/// (missing, truncated) or InvalidInput (not float raw NRRD, other sizes).
std::vector<float> read_map_nrrd(const std::filesystem::path& path, const CylinderGrid& grid);

}  // namespace caps

#pragma once
// Internal: a small VTK XML UnstructuredGrid (ascii) writer and reader for the fem files.

#include <Eigen/Core>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "caps/fem/mesh.hpp"

namespace caps::fem::detail {

/// A named data array: #rows × components (doubles; written as Int32 when `integer`).
struct VtuArray {
  std::string name;
  Eigen::MatrixXd values;
  bool integer = false;
};

/// Writes points + Hex20/Wedge15/Tet10 cells (VTK types 25/26/24, converted to VTK order) with
/// point and cell arrays.
void write_vtu(const std::filesystem::path& path, const Eigen::MatrixX3d& points,
               const std::vector<Element>& elements, const std::vector<VtuArray>& point_data,
               const std::vector<VtuArray>& cell_data);

/// Parsed content of an ascii .vtu: every DataArray by name ("Points" for the coordinates).
struct VtuContent {
  std::map<std::string, std::vector<double>> arrays;
  std::map<std::string, int> components;
  long n_points = 0, n_cells = 0;
};
VtuContent read_vtu(const std::filesystem::path& path);

}  // namespace caps::fem::detail

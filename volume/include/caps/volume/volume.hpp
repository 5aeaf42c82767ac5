#pragma once
/// @brief The image volume type every reader produces: voxels plus physical geometry.
///
/// Frame: patient LPS millimetres, as DICOM and ITK use (x towards the patient's Left, y towards
/// Posterior, z towards Superior). Voxel (i, j, k) sits at
///   p = origin_lps + direction * diag(spacing_mm) * (i, j, k)^T,
/// with i the fastest-varying index in memory. Convert only through index_to_lps()/lps_to_index().

#include <Eigen/Core>
#include <Eigen/LU>
#include <cstdint>
#include <string>
#include <vector>

namespace caps {

enum class Modality { CT, MR, Unknown };

/// "CT", "MR" or "unknown".
const char* to_string(Modality m);

/// Grid geometry shared by volumes and masks.
struct VolumeGeometry {
  Eigen::Vector3i dims{0, 0, 0};                                  ///< (n_i, n_j, n_k) voxels
  Eigen::Vector3d spacing_mm{1, 1, 1};                            ///< voxel size along i, j, k
  Eigen::Vector3d origin_lps{0, 0, 0};                            ///< centre of voxel (0,0,0)
  Eigen::Matrix3d direction = Eigen::Matrix3d::Identity();        ///< columns: i, j, k in LPS

  std::size_t n_voxels() const {
    return static_cast<std::size_t>(dims[0]) * dims[1] * dims[2];
  }
  std::size_t linear(int i, int j, int k) const {
    return (static_cast<std::size_t>(k) * dims[1] + j) * dims[0] + i;
  }
  bool contains(int i, int j, int k) const {
    return i >= 0 && j >= 0 && k >= 0 && i < dims[0] && j < dims[1] && k < dims[2];
  }
  /// Continuous voxel index (i, j, k) to LPS mm.
  Eigen::Vector3d index_to_lps(const Eigen::Vector3d& ijk) const {
    return origin_lps + direction * spacing_mm.cwiseProduct(ijk);
  }
  /// LPS mm to continuous voxel index.
  Eigen::Vector3d lps_to_index(const Eigen::Vector3d& p) const {
    return (direction.inverse() * (p - origin_lps)).cwiseQuotient(spacing_mm);
  }
};

/// A scalar volume. CT values are Hounsfield units; MR values are arbitrary units.
struct Volume {
  VolumeGeometry geom;
  std::vector<float> data;  ///< geom.n_voxels() values, i fastest
  Modality modality = Modality::Unknown;
  std::string source;       ///< file or folder it came from, for messages
  std::string format;       ///< "DICOM", "NIfTI-1", "NRRD", "MetaImage", "InVesalius", "phantom"
  std::vector<std::string> notes;  ///< what the reader did (resampling, series choice, ...)
  /// 1 where the scanner acquired data, 0 where a reader filled in (e.g. outside a tilted
  /// slab after resampling); empty means everywhere.
  std::vector<std::uint8_t> acquired;

  float at(int i, int j, int k) const { return data[geom.linear(i, j, k)]; }
  float& at(int i, int j, int k) { return data[geom.linear(i, j, k)]; }
  Eigen::Vector3d index_to_lps(const Eigen::Vector3d& ijk) const { return geom.index_to_lps(ijk); }
  Eigen::Vector3d lps_to_index(const Eigen::Vector3d& p) const { return geom.lps_to_index(p); }
};

/// A binary mask on a volume grid (0 or 1 per voxel).
struct Mask {
  VolumeGeometry geom;
  std::vector<std::uint8_t> data;

  std::uint8_t at(int i, int j, int k) const { return data[geom.linear(i, j, k)]; }
  std::size_t count() const;
};

/// True if the LPS point lies within `margin_voxels` of the edge of the acquired data: the grid's
/// boundary or, where Volume::acquired is set, a voxel that was filled in.
bool near_data_edge(const Volume& v, const Eigen::Vector3d& p_lps, double margin_voxels);

/// Trilinear interpolation at a continuous voxel index; outside the grid returns `outside`.
float sample_trilinear(const Volume& v, const Eigen::Vector3d& ijk, float outside);

/// Checks that a freshly read volume is usable: positive dims and spacing, finite values, a
/// non-singular direction, data size matching dims. Throws InvalidInput naming `v.source`.
void validate_volume(const Volume& v);

}  // namespace caps

#pragma once
/// @brief Narrow-band signed distance fields of closed surfaces (OpenVDB level sets, kept in the
/// .cpp): the exact distance (mm) from any point near the skin or the bone to that surface, its
/// closest point and normal, for the whole-face tissue model (mesher/tissue_model.hpp) and
/// skin/bone contact. Written and read as OpenVDB .vdb files (Blender and Houdini open them).

#include <Eigen/Core>
#include <filesystem>
#include <memory>
#include <string>

#include "caps/core/mesh.hpp"
#include "caps/volume/volume.hpp"

namespace caps {

/// A signed distance field of a closed triangle mesh on a sparse grid: negative inside, positive
/// outside, |value| = distance to the nearest point of the surface (mm), within a band around it.
class SignedDistanceField {
 public:
  /// Builds the field of `mesh` (V LPS mm, F triangles; closed, outward-facing) on a grid of
  /// `voxel_mm` cubes, `exterior_mm` outside and `interior_mm` inside the surface (the band).
  /// Throws InvalidInput for an empty mesh or non-positive sizes.
  static SignedDistanceField from_mesh(const TriMesh& mesh, double voxel_mm, double exterior_mm,
                                       double interior_mm);

  /// Builds the field of the boundary of a binary mask (inside = mask voxels), on cubes of
  /// `voxel_mm` (world space = LPS mm) with a band of `exterior_mm` outside and `interior_mm`
  /// inside. The surface is the 0.5 level of the mask's 3x3x3 box mean (sub-voxel, without the
  /// voxels' stairs): near it the distance is (0.5 - mean) x 3 voxels, farther the mask's exact
  /// distance transform; sampled onto the cubes and solved again from the zero level by fast
  /// sweeping (OpenVDB sdfToSdf). Far values are +-max(exterior_mm, interior_mm). Where the mask
  /// touches its grid's border (the CT's field of view), its border slices are carried on
  /// outward beyond the band, so the surface continues through the cut instead of being capped
  /// there. Throws InvalidInput for an empty mask or non-positive sizes.
  static SignedDistanceField from_mask(const Mask& mask, double voxel_mm, double exterior_mm,
                                       double interior_mm);

  /// Reads a level set written by write() (the first float grid of an OpenVDB .vdb file, of the
  /// level-set class, on cubic voxels). Throws IoError if the file cannot be opened,
  /// InvalidInput if it is not such a file or holds no such grid.
  static SignedDistanceField read(const std::filesystem::path& path);

  /// Writes the field as an OpenVDB .vdb file holding one float level-set grid named `name`
  /// (world space LPS mm), atomically. Throws IoError.
  void write(const std::filesystem::path& path, const std::string& name) const;

  /// The signed distance (mm) at an LPS point, trilinear between voxels; outside the band it is
  /// +exterior_mm (outside) or -interior_mm (inside).
  double operator()(const Eigen::Vector3d& p_lps) const;
  /// Its gradient (unit near the surface; zero outside the band), by central differences.
  Eigen::Vector3d gradient(const Eigen::Vector3d& p_lps) const;
  /// The outward unit normal of the level set through p (the normalised gradient); zero where
  /// the gradient vanishes (outside the band).
  Eigen::Vector3d normal(const Eigen::Vector3d& p_lps) const;
  /// The closest point of the surface (the zero level) to p: p - phi grad phi, repeated until it
  /// moves less than a hundredth of a voxel (at most 5 steps). Meaningful inside the band;
  /// outside it p is returned unchanged.
  Eigen::Vector3d closest_point(const Eigen::Vector3d& p_lps) const;
  double voxel_mm() const;
  /// The band's half-widths (mm): the values the field takes far outside / inside.
  double exterior_mm() const;
  double interior_mm() const;
  /// Active voxels of the sparse grid (its memory is about 4-8 bytes each).
  std::size_t n_active_voxels() const;
  /// True once built or read.
  bool is_valid() const { return impl_ != nullptr; }

 private:
  struct Impl;
  std::shared_ptr<const Impl> impl_;  // shared: the field is immutable once built
};

}  // namespace caps

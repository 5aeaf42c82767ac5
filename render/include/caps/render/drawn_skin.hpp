#pragma once
/// @brief The skin that is drawn: a range image on the model's grid resampled, sub-voxel, from the
/// smoothed isosurface (the model's skin.ply), with the CT's slice terraces removed by a box
/// filter one slice long along the axis.
///
/// The model's own r_skin is measured straight from the voxels along each radial ray; across a
/// sloping surface (the forehead) it steps once per CT slice, and those terraces showed in every
/// picture as horizontal bands. The drawn skin is
///   1. r_iso(theta, z): the outermost crossing of the radial ray with the smoothed isosurface
///      (Embree), where it lies within kDrawnSkinMaxShiftMm of the model's r_skin (elsewhere, and
///      where the ray misses the surface, the model's r_skin is kept);
///   2. the terrace filter: r_drawn(z) = (1 / w) integral of r_iso over [z - w/2, z + w/2], w the
///      slice spacing along the axis. A box exactly one slice period long has zeros at the
///      slice frequency and all its harmonics, so a staircase of that period is removed whatever
///      its phase, while detail longer than a few slices (eyelids, nostrils, lips: 5 mm and more)
///      keeps most of its amplitude (a 4-slice-long wave keeps 90 %). Along theta nothing is
///      filtered (the slices do not step there).
///      The window is sampled by rays of its own (8 per sample, at z + (i + 0.5) w / 8 - w / 2),
///      not interpolated between grid rows, so the staircase is averaged over exactly one period
///      whatever the grid spacing (a staircase sampled at 0.62 mm and interpolated is not periodic
///      in 1.5 mm any more). Without an isosurface the model's r_skin is filtered the same way,
///      interpolated linearly between rows.
/// Undercuts: where a ray leaves the isosurface and meets it again after an air gap of at least
/// kUndercutMinGapMm (ears, under the nose and the chin), the range image cannot show the skin
/// (a ray meeting the surface more than 75 degrees from its normal is grazing it, as over the top
/// of the head, and is not taken for an undercut).
/// Those cells, and those of the model's samples whose ray grazes the skin (kGrazing: the top of
/// the head, the nose's flanks, the sides of a local chart's band, which a range image draws as
/// a staircase of streaks), dilated by two, are not drawn from the range image: the isosurface's
/// own triangles are (those whose centroid falls in the cells dilated by three, so that they
/// overlap the range cells' border rather than leave a gap), with the isosurface's vertex
/// normals. The range flags' kUndercut stays the undercuts' alone.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "caps/core/mesh.hpp"
#include "caps/core/reporter.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps::render {

/// The drawn range keeps the model's r_skin where the isosurface's crossing differs by more than
/// this (mm): there the ray met another part of the surface than the model did.
inline constexpr double kDrawnSkinMaxShiftMm = 3.0;

/// The skin drawn: the range image, and the isosurface's triangles where the range cannot show
/// the skin (undercuts, grazing rays).
struct DrawnSkin {
  PatientModel range;  ///< the model with r_skin resampled and filtered (same grid and colour)
  TriMesh undercuts;   ///< isosurface triangles drawn in the undercut cells (LPS mm); may be empty
  Eigen::MatrixX3d undercut_normals;  ///< #undercuts.V×3 unit vertex normals of the isosurface
  /// grid.size() flags, 1 for a range cell (j, k) (samples j..j+1, k..k+1) left out for
  /// `undercuts`; empty: none
  std::vector<std::uint8_t> undercut_cells;
};

/// How the drawn skin is made.
struct DrawnSkinOptions {
  /// Length (mm) of the terrace filter along the axis: the CT's slice spacing; 0 = no filter.
  double slice_spacing_mm = 0;
};

/// The drawn skin of `model`: its range, a copy of `model` (same grid, axis, colour) whose r_skin
/// is resampled from `isosurface` (V #V×3 LPS mm, F #F×3, closed; null: the model's r_skin) and
/// filtered along z, and the isosurface's triangles in the undercuts (see @brief). Throws
/// InvalidInput for a negative or non-finite slice spacing.
DrawnSkin drawn_skin(const PatientModel& model, const TriMesh* isosurface,
                     const DrawnSkinOptions& options = {});

/// drawn_skin() of a model directory: the isosurface is its model.json "skin_mesh"
/// (skin.ply), the slice spacing the source volume's third spacing (model.json
/// source.spacing_mm; a scan model has none: no filter). Without a skin mesh the model's r_skin
/// is filtered alone, with a warning through `reporter`. Throws IoError if model.json or the mesh
/// cannot be read.
DrawnSkin load_drawn_skin(const PatientModel& model, const std::filesystem::path& model_dir,
                             Reporter* reporter = nullptr);

/// The slice terraces of a range image, a number for tests and benchmarks: over the grid samples
/// with theta in [theta_lo, theta_hi] and z in [z_lo, z_hi] (degrees, mm), the RMS (degrees) of
/// the second difference along z of the surface's tilt, phi_k = atan(dr/dz) (central differences):
/// phi_{k+1} - 2 phi_k + phi_{k-1}. The normal turns by about phi per row; on a smooth surface
/// that turn changes slowly (dz^2 phi'': hundredths of a degree at a 1 mm grid on a head) while
/// terraces turn it back and forth by degrees every slice. Throws InvalidInput for an empty region.
double terrace_rms_deg(const PatientModel& skin, double theta_lo, double theta_hi, double z_lo,
                       double z_hi);

}  // namespace caps::render

#pragma once
/// @brief Suture forces in the terms surgeons use: the closing force of each suture when
/// sutures are placed every `spacing_mm` along the closed wound, the largest of them, and the
/// force per mm of wound, beside the whole wound's closing force (SolveResult).
///
/// The solver's suture pairs are nodal constraints at every depth of the wound's wall; a surgeon's
/// suture holds a stretch of the wound over the whole depth. So the pairs are grouped by where
/// their column meets the skin after closure, those sites are gathered into sutures `spacing_mm`
/// apart along the closed wound, and each suture carries the closing force of its pairs (the
/// pair's force along the gap it closes, as in SolveResult::total_suture_force_n). A suture
/// cannot push: one whose pairs push the lips apart in sum (a negative force) is reported apart
/// (SutureSpacing::compressive) and is in no total; the tensile sutures and the compressive ones
/// add up to SolveResult::total_suture_force_n, the net force across the wound.
///
/// Single nodal pairs are not sutures: quadratic elements' consistent nodal forces make many of
/// them negative where the wound is pulled shut, so pairs are judged only in sum, by the suture
/// that holds them (docs/fem.md, "Suture forces in surgeons' terms").

#include <Eigen/Core>
#include <vector>

#include "caps/fem/continuum_mesher.hpp"
#include "caps/fem/solve.hpp"

namespace caps::fem {

/// One suture of the row.
struct SutureStitch {
  Eigen::Vector3d position_mm{0, 0, 0};  ///< where it sits on the closed skin, LPS mm
  double force_n = 0;                    ///< its closing force, N
  int n_pairs = 0;                       ///< nodal suture pairs it holds (all depths)
};

/// The row of sutures and its summary.
struct SutureSpacing {
  double spacing_mm = 5;              ///< the spacing asked for
  double wound_length_mm = 0;         ///< the closed wound's length on the skin (all its lines)
  std::vector<SutureStitch> sutures;  ///< the tensile ones (force >= 0), along the wound
  /// The sutures whose pairs push in sum (force < 0): where the closure presses the lips
  /// together. Reported apart: in no total, maximum, mean or force per mm.
  std::vector<SutureStitch> compressive;
  double max_suture_force_n = 0;      ///< the largest single-suture force, N
  double mean_suture_force_n = 0;     ///< over the tensile sutures, N
  double force_per_mm_n = 0;          ///< total_force_n / wound length, N/mm
  double total_force_n = 0;           ///< the sum over the tensile sutures, N
  double compressive_force_n = 0;     ///< the sum over the compressive ones (<= 0), N
};

/// The largest force on one sutured node pair (N): max over result.suture_forces of magnitude_n.
double max_suture_pair_force_n(const SolveResult& result);

/// Groups the closing force of `result` (a solve of `mesh.mesh`) into sutures every `spacing_mm`
/// along the closed wound. Each pair sits where its column (found up through the elements, not
/// by its (theta, z), which the two lips of a cut share) meets the skin after closure; every
/// such site is within spacing_mm of a suture. The wound's length is the minimum spanning tree
/// of the closed skin sites (the suture lines of a Z are one tree). Throws InvalidInput if
/// spacing_mm is not > 0 or the result does not belong to the mesh; a mesh without sutures gives
/// an empty row.
SutureSpacing suture_spacing(const ContinuumMesh& mesh, const SolveResult& result,
                             double spacing_mm = 5.0);

}  // namespace caps::fem

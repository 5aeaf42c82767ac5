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

#include "caps/mesher/continuum_mesher.hpp"
#include "caps/fem/solve.hpp"
#include "caps/fem/suture_report.hpp"

namespace caps::closure {

/// Groups the closing force of `result` (a solve of `mesh.mesh`) into sutures every `spacing_mm`
/// along the closed wound. Each pair sits where its column (found up through the elements, not
/// by its (theta, z), which the two lips of a cut share) meets the skin after closure; every
/// such site is within spacing_mm of a suture. The wound's length is the minimum spanning tree
/// of the closed skin sites (the suture lines of a Z are one tree). Throws InvalidInput if
/// spacing_mm is not > 0 or the result does not belong to the mesh; a mesh without sutures gives
/// an empty row.
fem::SutureSpacing suture_spacing(const mesher::ContinuumMesh& mesh, const fem::SolveResult& result,
                             double spacing_mm = 5.0);

}  // namespace caps::closure

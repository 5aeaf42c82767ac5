#pragma once
/// @brief The report of one plan on several models of one patient (`caps compare-models`): each
/// model's result, and the difference maps on the reference's skin (displacement difference in
/// mm, tension difference in kPa) side by side, with the numbers in a table and the warnings.

#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

#include "caps/core/reporter.hpp"
#include "caps/study/compare_models.hpp"
#include "caps/render/render.hpp"
#include "caps/render/skin_surface.hpp"

namespace caps::render {

/// Where two simulated skins differ, at the reference skin's vertices.
struct SkinDifference {
  /// #V of the reference skin: |u_other - u_reference| (mm), u_other (the other skin's
  /// displacement at its vertex nearest to the reference vertex carried into its frame) taken
  /// back into the reference's frame by the inverse of the transform's linear part.
  Eigen::VectorXd displacement_mm;
  Eigen::VectorXd tension_kpa;  ///< #V: tension_other - tension_reference (kPa, signed)
  std::vector<char> matched;    ///< #V: the other skin has a vertex within match_mm
  double max_displacement_mm = 0;  ///< over the matched vertices
  double p99_abs_tension_kpa = 0;  ///< 99th percentile of |tension difference| on the FE mesh
};

/// The differences of `other` from `reference` (displaced_skin()s of two simulations).
/// @param reference_tension_kpa  #V(reference) tension at its vertices (tension_map().value)
/// @param other_tension_kpa      #V(other)
/// @param reference_to_other     4×4 similarity, the reference's LPS mm to the other's
/// @param match_mm               a reference vertex farther than this from every vertex of the
///                               other's skin is unmatched (difference 0)
SkinDifference skin_difference(const SkinSurfaces& reference, const Eigen::VectorXd& reference_tension_kpa,
                               const SkinSurfaces& other, const Eigen::VectorXd& other_tension_kpa,
                               const Eigen::Matrix4d& reference_to_other, double match_mm = 2.0);

/// Writes the report into an existing folder: <key>/ for each side (closure::write_simulation and
/// its post_plan.png and pre_plan.png with the plan's lines), for each side but the reference
/// difference_<key>_displacement.png and difference_<key>_tension.png (the reference's skin
/// after the closure, seen along the plan's normal, one colour scale for all sides),
/// model_comparison.json and report.html.
/// @param models  the sides' models, in the order of c.sides (not owned)
void write_model_comparison_report(const study::ModelComparison& c,
                                   const std::vector<const PatientModel*>& models,
                                   const closure::SimulateOptions& options,
                                   const std::filesystem::path& dir, const std::string& plan_name,
                                   const RenderOptions& render_options = {},
                                   Reporter* reporter = nullptr);

}  // namespace caps::render

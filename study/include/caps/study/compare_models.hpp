#pragma once
/// @brief One plan on several models of one patient (`caps compare-models`): the CT model (the
/// reference, measured thickness), the model built from a surface scan alone (constant
/// thickness, the 1992 way) and the model fused from both. The plan is placed at the same
/// anatomical point and in the same direction on each model: its centre and direction are
/// carried from the reference's frame into each model's frame by a similarity transform (for a
/// scan-built model, the registration's scan-to-CT matrix composed with the scan model's own
/// file-to-LPS map), and the template is laid out there again on that model's skin.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "caps/core/reporter.hpp"
#include "caps/study/compare.hpp"
#include "caps/closure/simulate.hpp"
#include "caps/plan/plan.hpp"

namespace caps::study {

/// A model compared with the reference, and where the reference's points lie in it.
struct ComparedModel {
  std::string key;                       ///< short name for folders and JSON: "ct", "scan", "fused"
  std::string label;                     ///< e.g. "scan (constant 6 mm)"
  const PatientModel* model = nullptr;   ///< not owned; must outlive compare_models()
  /// p_model = T [p_reference; 1]: the reference's LPS mm to this model's LPS mm, a similarity
  /// (rotation, uniform scale, translation).
  Eigen::Matrix4d reference_to_model = Eigen::Matrix4d::Identity();
};

/// Where transfer_plan() put the plan on the other model.
struct TransferredPlan {
  plan::Plan plan;               ///< laid out on the target model (model_hash is the target's)
  /// The distance (mm) from the reference's centre carried into the target's frame to the
  /// target's skin point on the ray from its axis through it: how far the two skins disagree at
  /// the plan's centre.
  double centre_gap_mm = 0;
};

/// The plan of `from` laid out on `to` at the same anatomical point and direction. The centre's
/// skin point p (LPS, `from`) becomes q = T p in `to`'s frame and the plan's centre is `to`'s
/// (theta, z) of q (the ray from its axis through q); the plan's direction, the unit tangent
/// e_x of its frame at the centre, becomes the linear part of T applied to e_x and is measured
/// in `to`'s tangent plane there as an orientation (deg from superior towards +theta). A
/// template of the procedure library is laid out again from its parameters; any other plan from
/// its points in its local frame (plan::procedure_from_plan()). Lengths stay in mm.
/// @param from_to_to  4×4 similarity, `from`'s LPS mm to `to`'s LPS mm
/// Throws InvalidInput if T is not a finite similarity or the centre falls off `to`'s grid.
TransferredPlan transfer_plan(const plan::Plan& plan, const PatientModel& from,
                              const PatientModel& to, const Eigen::Matrix4d& from_to_to);

/// The unit tangent (LPS) of a plan's x axis at its centre on `model`.
Eigen::Vector3d plan_direction(const plan::Plan& plan, const PatientModel& model);

struct ModelComparisonSide {
  std::string key, label;
  plan::Plan plan;        ///< as placed on this model
  closure::Simulation simulation;
  SimulationSummary summary;
  Eigen::Matrix4d reference_to_model = Eigen::Matrix4d::Identity();
  double centre_gap_mm = 0;  ///< see TransferredPlan (0 for the reference)
};

struct ModelComparison {
  std::vector<ModelComparisonSide> sides;  ///< [0] the reference, then the others in order
  /// Every side's warnings (its mesh's and its placement's), prefixed with its label.
  std::vector<std::string> warnings;
};

/// Simulates `plan` (placed on the reference model) on it and, carried over by
/// transfer_plan(), on each other model, each with its own thickness (the model's: measured for
/// a CT model, its constant for a scan-built one). Every side uses the surface mesh extent the
/// reference's run settled on, so that the meshes cover the same skin. A side's plan centre
/// more than 3 mm off the carried point is warned about (the skins disagree there).
/// Throws what simulate() throws, naming the side.
/// `reference.reference_to_model` must be the identity.
ModelComparison compare_models(const ComparedModel& reference, const plan::Plan& plan, const std::vector<ComparedModel>& others,
                               const closure::SimulateOptions& options = {}, Reporter* reporter = nullptr);

/// The comparison's table as JSON (model_comparison.json): the plan and, for each side, its
/// label, placement (theta, z, orientation, centre gap) and summary.
std::string model_comparison_json(const ModelComparison& c, const std::string& plan_name);

}  // namespace caps::study

#pragma once
/// @brief Whether a plan can be operated: its structure (paths, loop, excisions, sutures), its
/// geometry (no crossing or overlapping cuts), and its place on the patient model (every loop
/// point and a dense sampling of every loop edge on valid cells).

#include <optional>
#include <string>
#include <vector>

#include "caps/plan/plan.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps::plan {

/// One sutured edge pair and the lengths of its edges on the skin, mm.
struct SutureLength {
  int index = 0;                    ///< into Plan::sutures
  double first_mm = 0, second_mm = 0;
  double ratio() const;             ///< longer / shorter (>= 1)
};

/// What check_plan() found in a plan that can be operated.
struct PlanReport {
  int n_points = 0, n_loop = 0, n_sutures = 0;
  double cut_length_mm = 0;                  ///< the cutting paths' length on the skin
  std::vector<SutureLength> suture_lengths;
  std::vector<std::string> warnings;         ///< e.g. sutured edges of very different lengths
  /// The plan's centre from the nearest found landmark (nearest_landmark_placement()), where the
  /// caller knows the model's landmarks: how a surgeon finds the spot on the patient.
  std::optional<LandmarkPlacement> near;
};

/// check_plan()'s refusal where the model's cylindrical image cannot hold the skin under the
/// plan (undercut or grazing cells, and nothing worse: not the eye, not beyond the scan), which
/// a local chart facing that skin can (surface/chart.hpp; caps plan new makes one).
class SkinNotHeld : public InvalidInput {
 public:
  using InvalidInput::InvalidInput;
};

/// Sutured edges whose lengths differ by more than this factor get a warning.
inline constexpr double kSutureRatioWarning = 1.5;

/// Checks the plan's structure and geometry, without a model. Throws InvalidInput naming the
/// offending point, path segment, loop node, excision or suture: paths that are not a tree,
/// zero-length or crossing or overlapping segments, excision offsets that make the border cross
/// itself, suture edges that are not border edges or are used twice.
PlanReport check_plan_structure(const Plan& plan);

/// check_plan_structure(), then on the model: every loop point inside the model's z range and on
/// cells with flags 0, and every loop edge sampled every 0.25 mm likewise (the message names the
/// point or edge and the flags); the lengths of sutured edges on the skin. Throws InvalidInput
/// (SkinNotHeld where a local chart would hold the skin).
PlanReport check_plan(const Plan& plan, const PatientModel& model);

}  // namespace caps::plan

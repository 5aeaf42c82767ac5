#pragma once
// Where a request's "at" (or "at_xyz") puts a point on a model, for app/src only: "THETA,Z", a
// landmark placement ("glabella+15,20") or an LPS point, as caps plan new, caps model site and
// caps model chart read them.

#include <Eigen/Core>
#include <optional>
#include <string>

#include "caps/app/loaded_model.hpp"
#include "caps/plan/placement.hpp"
#include "caps/surface/patient_model.hpp"
#include "model_result.hpp"
#include "numbers.hpp"

namespace caps::app {

/// How far (mm, along its ray from the model's axis) an LPS point given as on the skin may lie
/// from the skin the model's image holds there: a click on the skin the page draws lies within
/// a nose's or an ear's depth of it (the image holds the outermost skin along the ray); a point
/// farther is not on this patient's skin.
inline constexpr double kMaxOffSkinMm = 50.0;

/// (theta deg, z mm) of `at` on `model` (read from `model_dir`, whose landmarks a placement
/// uses), or with `at` empty of the LPS point `at_xyz` ("X,Y,Z" mm, on the skin within
/// kMaxOffSkinMm); `placement` receives the landmark placement when `at` is one. Throws
/// InvalidInput for text that is none of these, a landmark the model does not have, or a point
/// off the skin.
inline Eigen::Vector2d resolve_at(const std::string& model_dir, const PatientModel& model,
                                  const std::string& at, const std::string& at_xyz = "",
                                  std::optional<plan::LandmarkPlacement>* placement = nullptr) {
  if (at.empty()) {
    const auto t = parse_numbers<3>(at_xyz, "--at-xyz", "an LPS point X,Y,Z in mm");
    const Eigen::Vector3d x(t[0], t[1], t[2]);
    const CylindricalPoint c = model.to_cylindrical(x);
    if (model.has_z(c.z_mm)) {
      const double off = (model.skin_point(c.theta_deg, c.z_mm) - x).norm();
      if (std::isfinite(off) && off > kMaxOffSkinMm)
        throw InvalidParameter(cat("{at_xyz} ", at_xyz, ": the point lies ", std::lround(off),
                                   " mm from the skin (theta ", std::lround(c.theta_deg),
                                   " deg, z ", std::lround(c.z_mm),
                                   " mm on the model); give a point on the "
                                   "skin (caps model site MODEL --at THETA,Z --json gives one)"));
    }
    return {c.theta_deg, c.z_mm};
  }
  if (const auto p = plan::parse_landmark_placement(at)) {
    if (placement) *placement = p;
    return plan::resolve_placement(model, plan::model_landmarks(model_dir, model), *p);
  }
  const auto tz = parse_numbers<2>(at, "--at", "THETA,Z in degrees and mm, e.g. --at 0,95");
  return {tz[0], tz[1]};
}

/// The warning of a plan placed from a landmark whose measured soft tissue is implausible
/// (surface/landmarks.hpp, landmark_doubt()), or empty: plan new, check and simulate carry it.
inline std::string placement_doubt(const std::string& model_dir, const PatientModel& model,
                                   const std::optional<plan::LandmarkPlacement>& placement) {
  if (!placement) return {};
  // A plan on a local chart was placed from its parent's landmarks (caps plan new).
  const std::string parent = detail::chart_parent(model_dir);
  const Landmarks landmarks = parent.empty()
                                  ? plan::model_landmarks(model_dir, model)
                                  : plan::model_landmarks(parent, *loaded_model(parent));
  const Landmark* l = landmarks.find(placement->landmark);
  if (!l || l->doubt.empty()) return {};
  return cat("placed from the ", l->name, ", whose measured soft tissue is implausible: ", l->doubt);
}

}  // namespace caps::app

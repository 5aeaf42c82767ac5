#pragma once
/// @brief Placing a plan relative to an anatomical landmark: "glabella+15,20" is 15 mm towards
/// the patient's left and 20 mm up along the skin from the glabella (docs/landmarks.md).

#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>

#include "caps/plan/plan.hpp"
#include "caps/surface/landmarks.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps::plan {

/// Parses "NAME", "NAME+LEFT,UP" or "NAME-LEFT,UP" (mm; "glabella+15,20", "nasion-10,-5",
/// "pogonion+0,0"). Returns nullopt for text that does not start with a letter (the THETA,Z
/// form "0,95"). Throws InvalidInput for an unknown landmark name (listing the names) or offsets
/// that are not two finite numbers.
std::optional<LandmarkPlacement> parse_landmark_placement(const std::string& text);

/// The landmarks of the model directory `dir`: model.json's "landmarks" if it has them, else
/// found now on `model` (the model in that directory).
Landmarks model_landmarks(const std::filesystem::path& dir, const PatientModel& model);

/// (theta deg, z mm) reached from `from_tz` (theta deg, z mm) by a walk on the skin of
/// |left_up_mm| mm in the direction (left, up) of the skin's tangent frame there: a landmark's
/// offsets (resolve_placement()), or a point of a lesion's outline about its centre. `from_tz`
/// itself when left_up_mm is 0. Theta is not wrapped.
Eigen::Vector2d walk_left_up(const PatientModel& model, const Eigen::Vector2d& from_tz,
                             const Eigen::Vector2d& left_up_mm);

/// (theta deg, z mm) of the placement on `model`: from the landmark, a walk on the skin of
/// hypot(left_mm, up_mm) mm in the direction (left_mm, up_mm) of the skin's tangent frame there
/// (left = along +theta at constant z, up = the skin's superior direction perpendicular to it;
/// walk_on_skin(), a geodesic on a cylinder). Throws InvalidInput naming the landmark and why it
/// is absent when the model does not have it, or when the walk leaves the model.
Eigen::Vector2d resolve_placement(const PatientModel& model, const Landmarks& landmarks,
                                  const LandmarkPlacement& placement);

/// The point (theta deg, z mm) as the surgeon finds it: the found landmark nearest to it on
/// `model` (straight-line distance between the skin points, at most `max_mm`; among those found
/// with confidence >= 0.5 and no doubt about their depth, unless another lies at less than half
/// that distance) and the offsets
/// to the patient's left and up along the skin from it, so that resolve_placement() of the
/// answer gives the point back (step_on_skin(), the walk's inverse; the offsets are not
/// rounded here). nullopt when no landmark is found within `max_mm`.
std::optional<LandmarkPlacement> nearest_landmark_placement(const PatientModel& model,
                                                            const Landmarks& landmarks,
                                                            double theta_deg, double z_mm,
                                                            double max_mm = 80.0);

/// nearest_landmark_placement() from the landmarks model.json of `model_dir` keeps (nullopt
/// when it keeps none: finding them anew would cost more than a plan check).
std::optional<LandmarkPlacement> nearest_kept_landmark_placement(
    const std::filesystem::path& model_dir, const PatientModel& model, double theta_deg,
    double z_mm);

/// The placement as a surgeon reads it, offsets rounded to the millimetre: "12 mm to the
/// patient's left and 8 mm up from the glabella" (landmark_in_words()).
std::string placement_in_words(const LandmarkPlacement& placement);

}  // namespace caps::plan

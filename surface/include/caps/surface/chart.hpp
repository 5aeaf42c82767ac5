#pragma once
/// @brief Local charts: a cylinder whose axis faces one region of the skin, so that the paper's
/// range image represents skin that the head's own cylinder meets edge-on (the side of the nose)
/// or behind other skin.
///
/// The head's cylinder sees most of the skin face-on, but its rays graze the nasal sidewall and
/// the alae and meet some skin only behind other skin. A chart is the same kind of model (the
/// same maps, measured the same way in the same CT) on another axis: perpendicular to the skin's
/// normal at the chosen point, at `radius_mm` behind it, with theta = 0 pointing along that
/// normal. The chosen point is then at theta 0, z 0 of the chart, its ray along the normal, and
/// rays within a few centimetres of it meet the skin nearly face-on. docs/mesher.md says where
/// charts are used.

#include <Eigen/Core>

#include "caps/core/mesh.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps {

/// Where a chart looks and from where.
struct ChartFrame {
  Eigen::Vector3d point{0, 0, 0};   ///< the skin point it is centred on, LPS mm
  Eigen::Vector3d normal{0, 0, 1};  ///< the skin's outward unit normal there (the ray at theta 0)
  CylinderAxis axis;                ///< the chart's axis: point = axis.to_lps(0, 0, radius)
  double radius_mm = 0;             ///< from the axis to the point
};

/// The area-weighted outward normal of the faces of `skin` whose centroids lie within
/// `radius_mm` of `point` (a smooth estimate of the skin's normal where a range image cannot
/// give it). Throws InvalidInput when no face lies that close or their normals cancel.
Eigen::Vector3d mesh_normal_near(const TriMesh& skin, const Eigen::Vector3d& point,
                                 double radius_mm);

/// The chart frame at `point` with outward `normal`: the axis runs along `up` made perpendicular
/// to the normal (the parent model's axis direction keeps superior up in the chart; where the
/// normal is nearly along `up`, `fallback_up` is used), through point - radius_mm * normal, and
/// theta = 0 points along the normal. Throws InvalidInput for a radius outside (0, 1000] mm or
/// a zero normal.
ChartFrame chart_frame(const Eigen::Vector3d& point, const Eigen::Vector3d& normal,
                       const Eigen::Vector3d& up, const Eigen::Vector3d& fallback_up,
                       double radius_mm);

/// The chart frame at (theta, z) of a model: its skin point, the normal of its skin isosurface
/// `skin` there (mesh_normal_near within `normal_radius_mm`, oriented away from the model's
/// axis), up along the model's axis.
ChartFrame chart_frame(const PatientModel& model, const TriMesh& skin, double theta_deg,
                       double z_mm, double radius_mm, double normal_radius_mm);

}  // namespace caps

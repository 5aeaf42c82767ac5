#pragma once
/// @brief Soft-tissue anatomical landmarks found on the skin's range image r(theta, z): glabella,
/// nasion, pronasale, subnasale, pogonion and, on both sides, zygion, exocanthion and tragion
/// (Farkas' soft-tissue anthropometry; the definitions caps uses are in docs/landmarks.md),
/// each with a confidence and the soft-tissue thickness under it.
///
/// The detector reads only the range image: "anterior" is along the ray of the midline theta (the
/// pronasale's), "lateral" perpendicular to it in the axial plane, "up" along the model's axis.
/// Without a pronasale (a scan cut at the nose or above it) only the glabella and the nasion are
/// looked for, on the midline of the skin's left-right symmetry and at a lower confidence.
/// A landmark the skin does not show (outside the scan, no feature in its search window) is
/// returned with found = false and the reason, never guessed.

#include <Eigen/Core>
#include <limits>
#include <string>
#include <vector>

#include "caps/surface/patient_model.hpp"

namespace caps {

/// One landmark on a model. Positions on the skin: (theta deg, z mm) of the model's cylinder and
/// the LPS point; lengths in mm.
struct Landmark {
  std::string name;            ///< e.g. "glabella", "zygion_left" (landmark_names())
  bool found = false;          ///< false: absent, `note` says why
  double theta_deg = 0, z_mm = 0;
  Eigen::Vector3d lps{0, 0, 0};
  double confidence = 0;       ///< 0..1: how clearly the skin shows the feature (docs/landmarks.md)
  /// The soft-tissue thickness at the point along the skin normal (the model's thickness_normal
  /// map), mm; and its layers along the normal where the model has them (else NaN).
  double thickness_mm = 0;
  double skin_mm = std::numeric_limits<double>::quiet_NaN();
  double fat_mm = std::numeric_limits<double>::quiet_NaN();
  double deep_mm = std::numeric_limits<double>::quiet_NaN();
  /// Where the depth and layers are read when not at the point itself (theta deg, at z_mm):
  /// the tragion's in front of the ear, in the hollow before the tragus (the skin's lowest point
  /// within 15 mm in front of the ear's edge: at the edge the depth climbs with the ear's
  /// stand-off; docs/landmarks.md). NaN: at the point.
  double depth_theta_deg = std::numeric_limits<double>::quiet_NaN();
  bool measured = false;       ///< the skin and thickness there were measured, not filled
  std::string note;            ///< how it was found, or why it is absent
  /// Why its depth or layers are not plausible for this landmark (landmark_doubt()), or empty.
  std::string doubt;
};

/// Why a found landmark's soft-tissue depth or layers cannot be this landmark's, or empty: a
/// depth more than 4 SD from the adult T-Table mean where ../shared/docs/references.md gives one
/// (glabella 5.5 +- 1.0 mm, nasion 6.0 +- 1.5 mm), deeper than 20 mm anywhere (the T-Table's
/// deepest facial landmark, the philtrum, is 11.5 +- 2.5 mm: the ray meets the nose's
/// cartilage, the orbit or a cavity; the pronasale over 15 mm: its depth is through cartilage),
/// or a CT skin layer over 8 mm (dermis is 1-4 mm).
std::string landmark_doubt(const Landmark& landmark);

/// One relation of the midline's landmarks along the head's axis that an adult or a child's
/// face keeps (withdraw_contradicted()): `upper` lies `min_mm`..`max_mm` above `lower`.
struct LandmarkOrder {
  const char* upper;
  const char* lower;
  double min_mm, max_mm;
};

/// The relations withdraw_contradicted() checks: glabella 5..35 mm above the nasion, the nasion
/// 15..60 mm above the pronasale and 30..70 mm above the subnasale (the nose's height n-sn, 50-53
/// +- 3 mm in Farkas' adults, about 40 mm at five years), the pronasale 5..35 mm above the
/// subnasale, the subnasale 25..90 mm above the pogonion, the exocanthions -10..30 mm below the
/// nasion. Wide enough for children and a head tilted 30 deg in the scanner; a feature taken for
/// its neighbour (a nose tip for the glabella) breaks them.
const std::vector<LandmarkOrder>& landmark_orders();

/// Why the soft tissue the CT measured at a point of the face cannot be the layer a flap is
/// raised in, or empty: deeper than `kMaxFacialTissueMm` (the T-Table's deepest facial landmark,
/// the philtrum, is 11.5 +- 2.5 mm: the normal meets the nose's cartilage, the orbit or a
/// cavity), or a skin layer over `kMaxSkinLayerMm` (dermis is 1-4 mm). `skin_mm` NaN: no
/// layers. landmark_doubt(), caps model site and a closure's warnings use it.
inline constexpr double kMaxFacialTissueMm = 20.0;
inline constexpr double kMaxSkinLayerMm = 8.0;
std::string tissue_doubt(double thickness_mm, double skin_mm);

/// The landmarks of one model, in the order of landmark_names().
struct Landmarks {
  std::vector<Landmark> items;
  /// theta of the midsagittal profile (the pronasale's; without one, that of the skin's
  /// left-right symmetry, docs/landmarks.md; 0 when neither was found)
  double midline_theta_deg = 0;
  /// The landmark of that name, or nullptr for a name that is not a landmark.
  const Landmark* find(const std::string& name) const;
};

/// The names caps detects, in order: glabella, nasion, pronasale, subnasale, pogonion,
/// zygion_left, zygion_right, exocanthion_left, exocanthion_right, tragion_left, tragion_right.
const std::vector<std::string>& landmark_names();

/// A landmark's name as a surgeon says it, for messages: "glabella", "nasion", "nose tip
/// (pronasale)", "left outer eye corner (exocanthion)", "right tragus (tragion)"; a name that
/// is not a landmark is returned with its underscores as spaces.
std::string landmark_in_words(const std::string& name);

/// What the detector reads: the skin radius r(theta deg, z mm) in mm about the model's axis, where
/// it was measured, and the sampling steps and z extent of the range image.
struct SkinRangeView {
  std::function<double(double theta_deg, double z_mm)> r_mm;
  /// True where the skin at (theta, z) was measured (not filled, not undercut or truncated).
  std::function<bool(double theta_deg, double z_mm)> measured;
  /// True where the skin crosses the ray more than once (an ear): counts as ear in the search.
  std::function<bool(double theta_deg, double z_mm)> undercut;
  /// True where the soft tissue's depth at (theta, z) was measured (a valid cell): where the
  /// tragion's depth may be read. Unset: where the skin was measured.
  std::function<bool(double theta_deg, double z_mm)> depth_measured;
  double z_min_mm = 0, z_max_mm = 0;   ///< the range image's extent along the axis
  double dtheta_deg = 1, dz_mm = 1;    ///< the sampling steps of the search
  double r_typical_mm = 90;            ///< a typical radius, to turn mm along the skin into degrees
};

/// Finds the landmarks on a range image (theta, z, found, confidence, note; lps and the
/// thicknesses are left for the caller). Never throws for a head without a feature: that
/// landmark is absent.
Landmarks find_landmarks(const SkinRangeView& view);

/// Withdraws every found landmark when two contradict each other (landmark_orders(): a pair out
/// of order or out of distance along the head's axis): each is found from the midline profile
/// and from the others, so one out of place leaves none to trust. A withdrawn landmark is absent
/// (found false) and its note says why: nothing is placed from it. find_landmarks() and
/// landmarks_from_json() apply it. Returns how many were withdrawn.
int withdraw_contradicted(Landmarks& landmarks);

/// The least distance (mm) between the two outer eye corners of a face: an adult's are 85-95 mm
/// apart and a child's more than 60 mm (biocular width ex-ex; Farkas, Anthropometry of the Head
/// and Face, 1994; docs/landmarks.md).
inline constexpr double kMinBiocularWidthMm = 60.0;

/// Withdraws both exocanthions when they lie closer than kMinBiocularWidthMm to each other (LPS,
/// filled in): the depressions found are not the eyes' outer ends (on Cranium they lie 43 mm
/// apart), and a sheet or a plan said from them would be measured from the wrong place.
/// find_landmarks() and landmarks_from_json() apply it after withdraw_contradicted(); returns how
/// many were withdrawn (0 or 2).
int withdraw_narrow_eyes(Landmarks& landmarks);

/// The model's range view: bilinear r_skin, measured where every blended cell is valid and its
/// skin measured, undercut from the cells' flags; the grid's steps and extent.
SkinRangeView skin_range_view(const PatientModel& model);

/// Finds the landmarks on a model and fills in their LPS points (skin_point()) and the
/// soft-tissue thickness along the normal (and its layers where the model has them).
Landmarks find_landmarks(const PatientModel& model);

/// The landmarks as model.json's "landmarks" object (JSON text): {"definitions": "...",
/// "midline_theta_deg": t, "items": {name: {found, theta_deg, z_mm, lps, confidence,
/// thickness_mm, layers_mm?, measured, note}}}.
std::string landmarks_to_json(const Landmarks& landmarks);

/// Parses landmarks_to_json()'s text. Throws InvalidInput naming `source` for other text.
Landmarks landmarks_from_json(const std::string& text, const std::string& source);

/// A table for reading: one line per landmark (name, theta, z, LPS, confidence, thickness or the
/// reason it is absent).
std::string landmarks_table(const Landmarks& landmarks);

}  // namespace caps

#pragma once
/// @brief The relaxed skin tension lines (RSTL) on the patient: Borges's map of the face
/// (data/rstl/borges-1984.json) laid on the model by its landmarks (the midline, the nasion and
/// the subnasale), so a design can be read against the direction the textbooks excise along
/// (docs/plan.md, "Relaxed skin tension lines").
///
/// The map is schematic: ten zones of the face in a frame scaled by the nose's height, each with
/// the direction Borges draws there (fixed, radiating from a point, or concentric about one),
/// for the patient's left and mirrored onto the right. It stands for the textbook's rule, not
/// for this patient's skin; the closure's own least-force direction is the model's answer, and
/// the suggestion reports where the two disagree.

#include <optional>
#include <string>
#include <vector>

#include "caps/surface/landmarks.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps::plan {

/// One zone of the map (data/rstl/*.json).
struct SkinLineZone {
  std::string name;   ///< "forehead"
  std::string words;  ///< where, after "the lines": "on the forehead"
  std::string says;   ///< how they run, after "run": "horizontally"
  /// Where: u and v in [min, max] (the map's frame, below), or within radius of a point.
  double u_min = 0, u_max = 0, v_min = 0, v_max = 0;
  bool round = false;
  double cu = 0, cv = 0, radius = 0;
  /// Which lines: fixed (orientation deg on the left side), radial from (pu, pv), or concentric
  /// about it.
  enum class Kind { Fixed, Radial, Concentric } kind = Kind::Fixed;
  double fixed_deg = 0, pu = 0, pv = 0;
};

/// A map of the skin lines.
struct SkinLineMap {
  std::string name, source;
  std::vector<SkinLineZone> zones;
};

/// The map in data/rstl/borges-1984.json (read once). Throws IoError/InvalidInput if it is
/// missing or malformed.
const SkinLineMap& borges_map();

/// Reads a map file. Throws IoError/InvalidInput naming the file and what is wrong.
SkinLineMap read_skin_line_map(const std::string& path);

/// Where a point lies in the map's frame, from the landmarks: u the skin point's distance from
/// the midsagittal plane (the model's axis and the landmarks' midline theta) over h, positive on
/// either side; v the height above
/// the nasion over h; h the nasion-subnasale height; left: the point is on the patient's left.
struct FaceFrame {
  double u = 0, v = 0, h_mm = 0;
  bool left = true;
};

/// The direction of the skin lines at one place.
struct SkinLineDirection {
  bool found = false;
  /// The lines' orientation, deg in [0, 180), from superior towards the patient's left (the
  /// plan's convention: an ellipse laid at this orientation has its scar along the lines).
  double orientation_deg = 0;
  std::string zone;
  std::string words;  ///< where, after "the lines": "on the forehead", "around the mouth"
  std::string says;   ///< how they run, after "run": "horizontally"
  FaceFrame at;
  std::string note;  ///< why not found (no nasion or subnasale; a point off the map's face)
};

/// The map's direction at (theta_deg, z_mm) on `model` with its `landmarks`: not found (with the
/// reason) where the landmarks the map is laid by are missing or the point lies in no zone.
SkinLineDirection skin_line_direction(const SkinLineMap& map, const PatientModel& model,
                                      const Landmarks& landmarks, double theta_deg, double z_mm);

/// One traced skin line: a short stretch of the map's direction field, through a seed point.
struct SkinLinePath {
  std::string zone;                    ///< the seed's zone
  std::vector<double> theta_deg, z_mm;  ///< the points on the model, 1 mm apart along the skin
};

/// The map drawn over the face, as the textbooks draw it: from seeds `spacing_mm` apart (in z
/// and along the skin around the axis; over the face within 90 deg of its midline, from 3 nose
/// heights below the nasion to 1.6 above it, about the hairline, where the model has skin), each
/// line traced along the map's direction (midpoint steps of 1 mm, measured as the plan's frame
/// measures it: r_skin d(theta) across, dz up) for up to `half_length_mm` either way, ending
/// where the map has no direction (off its face, no skin) or at its zone's border (where the
/// direction jumps). Empty, with `note` set as skin_line_direction sets it, where the map cannot
/// be laid on this model. Throws InvalidParameter for a spacing outside [4, 50] mm or a half
/// length outside [1, 30] mm (at most about ten thousand lines of 61 points).
std::vector<SkinLinePath> trace_skin_lines(const SkinLineMap& map, const PatientModel& model,
                                           const Landmarks& landmarks, double spacing_mm,
                                           double half_length_mm, std::string* note = nullptr);

/// The angle between two unoriented lines given as orientations (deg): 0..90.
double angle_between_lines_deg(double a_deg, double b_deg);

}  // namespace caps::plan

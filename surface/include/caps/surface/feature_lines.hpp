#pragma once
/// @brief Feature lines on the patient's skin, found on the skin's range image r(theta, z) beside
/// the anatomical landmarks (landmarks.hpp): the brows, the upper and lower eyelid margins, the
/// upper and lower lip vermilion borders, the oral commissures and the alar rims; and what a
/// displacement field (a closure's) does to them, in millimetres and anatomical words, with the
/// clinical thresholds where a displacement matters (docs/landmarks.md, "Feature lines and what a
/// closure does to them").
///
/// Each line is a crease (valley) or a ridge of the skin, followed column by column (or row by
/// row) in a search window placed relative to the landmarks in the adult face's proportions
/// (Farkas 1994): the extremum, across the line, of the skin's curvature along the range image's
/// row or column. A line the skin does not show (outside the scan, no crease in its window) is
/// returned with found = false and the reason, never guessed.

#include <Eigen/Core>

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "caps/surface/landmarks.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps {

/// One feature line on a model's skin.
struct FeatureLine {
  std::string name;    ///< e.g. "lower_eyelid_margin_left", "eyebrow_right" (feature_line_names())
  bool found = false;  ///< false: absent, `note` says why
  /// "left" or "right" (the patient's) for a paired line, "midline" for a lip border.
  std::string side;
  /// How its thirds are named: "medial-lateral" (brows, eyelids: points from medial to lateral),
  /// "right-left" (lip borders: points from the patient's right to left), "inferior-superior"
  /// (alar rims: points from below upwards), "point" (a commissure).
  std::string along;
  std::vector<Eigen::Vector2d> theta_z;  ///< (theta deg, z mm) on the model's cylinder
  std::vector<Eigen::Vector3d> lps;      ///< the skin points, LPS mm (one per theta_z)
  double confidence = 0;                 ///< 0..1: how clearly and continuously the skin shows it
  std::string method;                    ///< what was searched where (the window, the criterion)
  std::string note;                      ///< why it is absent, or what limits it
};

/// The feature lines of one model, in the order of feature_line_names().
struct FeatureLines {
  std::vector<FeatureLine> items;
  /// The line of that name, or nullptr.
  const FeatureLine* find(const std::string& name) const;
};

/// The names, in order: eyebrow_left/right, upper_eyelid_margin_left/right,
/// lower_eyelid_margin_left/right, upper_lip_vermilion, lower_lip_vermilion,
/// oral_commissure_left/right, alar_rim_left/right, hairline.
const std::vector<std::string>& feature_line_names();

/// A feature line's name in words: "lower_eyelid_margin_left" -> "the left lower eyelid margin",
/// "eyebrow_right" -> "the right brow", "upper_lip_vermilion" -> "the upper lip's vermilion border".
std::string feature_line_words(const std::string& name);

/// Finds the feature lines on a range view beside `landmarks` (found on the same view; their
/// theta_deg, z_mm and the midline are read). `r_bone` (theta deg, z mm -> mm; NaN where there is
/// no bone) guides the brows to the supraorbital rim; empty: the skin alone. The theta_z of each
/// line are filled, its lps left for the caller. Never throws for a face without a feature.
FeatureLines find_feature_lines(const SkinRangeView& view, const Landmarks& landmarks,
                                const std::function<double(double, double)>& r_bone = {});

/// The feature lines of a model (its range view, its bone where measured), with their LPS points
/// on the skin (skin_point()).
FeatureLines find_feature_lines(const PatientModel& model, const Landmarks& landmarks);

/// The lines as model.json's "features" object (JSON text): {"definitions": "...", "items":
/// {name: {found, side, along, confidence, method, note, theta_z: [[t, z], ...], lps: [[x, y,
/// z], ...]}}}.
std::string feature_lines_to_json(const FeatureLines& lines);

/// Parses feature_lines_to_json()'s text. Throws InvalidInput naming `source` for other text.
FeatureLines feature_lines_from_json(const std::string& text, const std::string& source);

/// A table for reading: one line per feature (name, points, length, z range, confidence, or the
/// reason it is absent).
std::string feature_lines_table(const FeatureLines& lines);

/// Draws the lines and the landmarks on a front view of the model's skin (an orthographic
/// projection onto the frontal plane, the patient's right on the left of the picture, Lambert
/// shaded) into a PNG, 4 pixels per mm, with a legend and a millimetre scale. Written atomically.
void write_feature_lines_png(const std::filesystem::path& path, const PatientModel& model,
                             const Landmarks& landmarks, const FeatureLines& lines,
                             const std::string& title);

/// The patient's anatomical directions, unit vectors in LPS: front (anterior), left (the
/// patient's left), up (superior). A model's: its axis' front, left and direction.
struct AnatomicalFrame {
  Eigen::Vector3d front{0, -1, 0}, left{1, 0, 0}, up{0, 0, 1};
};

/// The model's anatomical frame (its cylinder axis: front, left, direction).
AnatomicalFrame anatomical_frame(const PatientModel& model);

/// A displacement field on the skin: the displacement (mm, LPS) at a skin point (LPS mm), or
/// nothing where the field has no value (outside the closure's model).
using DisplacementAt = std::function<std::optional<Eigen::Vector3d>(const Eigen::Vector3d&)>;

/// A displacement field from samples of it (a closure's skin nodes and their displacements): at a
/// point, the inverse-distance-squared mean of the samples within `radius_mm` (the sample itself
/// where the point is one), nothing where no sample is that close (the closure's model does not
/// reach the point). The samples are binned in cells of the radius, so a query looks at its
/// neighbourhood only (the renderer asks it for every vertex of the skin).
/// @param points         #P×3 sample positions (LPS mm)
/// @param displacements  #P×3 displacements there (mm, LPS)
/// @param radius_mm      how far a sample speaks for (e.g. twice the mesh size)
DisplacementAt displacement_from_samples(const Eigen::MatrixX3d& points,
                                         const Eigen::MatrixX3d& displacements, double radius_mm);

/// A field carried on across a seam: within `width_mm` of the nearest of the samples `points`
/// (dense along a curve: the rim of a finely meshed patch tied to a coarser mesh around it), at a
/// distance d from it, (1 - d / width) times that sample's value plus d / width times `far`'s
/// (zero where `far` has none); `far` itself beyond. So a field that jumps across the seam (each
/// side's discretisation gives its own value there) goes on without an edge, equal to the
/// samples on the seam and to `far` a width away.
/// @param far       the field away from the seam
/// @param points    #P×3 sample positions along the seam (LPS mm)
/// @param values    #P×3 the field's values there
/// @param width_mm  how far from the seam the samples speak (> 0)
DisplacementAt blend_across_seam(DisplacementAt far, const Eigen::MatrixX3d& points,
                                 const Eigen::MatrixX3d& values, double width_mm);

/// A clinical threshold: the displacement of a feature, in one anatomical direction, beyond which
/// it matters, and where the number comes from (docs/landmarks.md's table).
struct ClinicalThreshold {
  std::string feature;    ///< the line names it applies to start with this ("lower_eyelid_margin")
  std::string direction;  ///< "down", "up", "vertical" (either), "any" (the whole displacement)
  double threshold_mm = 0;
  std::string risk;    ///< what it risks ("scleral show, ectropion")
  std::string source;  ///< author year, journal; or "no source found; a rule of thumb"
};

/// The thresholds caps warns at, one or more per feature (docs/landmarks.md).
const std::vector<ClinicalThreshold>& clinical_thresholds();

/// What a displacement field does to one feature line.
struct FeatureDisplacement {
  std::string name;
  bool found = false;      ///< the line was found on the model
  bool has_value = false;  ///< the field has a value at one of its points at least
  int n_points = 0, n_with_value = 0;
  double max_mm = 0;                    ///< the largest displacement's length
  double mean_mm = 0;                   ///< the mean length over the line (weighted by arc length)
  Eigen::Vector3d max_lps{0, 0, 0};     ///< the largest displacement (mm, LPS)
  Eigen::Vector3d max_at_lps{0, 0, 0};  ///< where on the line it is (LPS mm)
  /// The largest displacement's components in the anatomical frame (mm): up, lateral (away from
  /// the midline for a paired line, the patient's left for a midline one), forward.
  double up_mm = 0, lateral_mm = 0, forward_mm = 0;
  std::string direction;  ///< its dominant direction in words: "down", "up and laterally", ...
  std::string where;      ///< "medial third", "middle third", "right third", "inferior third", ...
  std::string sentence;   ///< "the lower eyelid margin is pulled 2.4 mm down at its middle third"
  std::string warning;    ///< the clinical warning where a threshold is passed, else empty
};

/// For each line of `lines`: the largest and mean displacement of `displacement_at` along it, the
/// largest one's place (third) and direction in `frame`'s words, a sentence, and a warning where
/// clinical_thresholds() are passed. An absent line, or one the field has no value on, says so in
/// its sentence. The hairline (never found on a CT) is left out when absent.
std::vector<FeatureDisplacement> feature_displacements(const FeatureLines& lines,
                                                       const DisplacementAt& displacement_at,
                                                       const AnatomicalFrame& frame);

/// One clause for a summary line: the sentence of the feature displaced most (among those with a
/// value), with how many warn ("the left lower eyelid margin is pulled 2.4 mm down at its middle
/// third; 1 feature warning"); empty when the field reaches no feature.
std::string feature_displacements_summary(const std::vector<FeatureDisplacement>& displacements);

/// The displacements as a JSON array (text) for result.json: [{name, found, has_value, max_mm,
/// mean_mm, direction_lps, direction, where, sentence, warning?}, ...] (max_mm and mean_mm null
/// without a value).
std::string feature_displacements_to_json(const std::vector<FeatureDisplacement>& displacements);

}  // namespace caps

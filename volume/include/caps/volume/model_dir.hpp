#pragma once
/// @brief The model directory (format 1, docs/model-format.md) in one place: the names of its
/// files, model.json as a struct (written from it and read into it here only), the writer of a
/// whole directory, and the readers of its maps and colour image.

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "caps/core/mesh.hpp"
#include "caps/core/reporter.hpp"
#include "caps/image/rgb_image.hpp"
#include "caps/volume/cylindrical_map.hpp"

namespace caps {

inline constexpr int kModelFormatVersion = 1;

/// The names of the files in a model directory.
namespace model_file {
inline constexpr char kJson[] = "model.json";
inline constexpr char kRSkin[] = "r_skin.nrrd";
inline constexpr char kRBone[] = "r_bone.nrrd";
inline constexpr char kThickness[] = "thickness.nrrd";
inline constexpr char kThicknessNormal[] = "thickness_normal.nrrd";
inline constexpr char kValidity[] = "validity.nrrd";
inline constexpr char kThicknessPng[] = "thickness.png";
inline constexpr char kSkinPng[] = "skin.png";
inline constexpr char kSkinMesh[] = "skin.ply";
inline constexpr char kBoneMesh[] = "bone.ply";
inline constexpr char kColor[] = "color.png";  ///< only where the source has colour
// The tissue layers, only where they were measured (CT): along the ray and along the normal,
// their validity (LayerFlag), and a picture of each layer along the normal.
inline constexpr char kThicknessSkin[] = "thickness_skin.nrrd";
inline constexpr char kThicknessFat[] = "thickness_fat.nrrd";
inline constexpr char kThicknessDeep[] = "thickness_deep.nrrd";
inline constexpr char kThicknessSkinNormal[] = "thickness_skin_normal.nrrd";
inline constexpr char kThicknessFatNormal[] = "thickness_fat_normal.nrrd";
inline constexpr char kThicknessDeepNormal[] = "thickness_deep_normal.nrrd";
inline constexpr char kLayerValidity[] = "layer_validity.nrrd";
inline constexpr char kLayerValidityNormal[] = "layer_validity_normal.nrrd";
inline constexpr char kLayerSkinPng[] = "layer_skin.png";
inline constexpr char kLayerFatPng[] = "layer_fat.png";
inline constexpr char kLayerDeepPng[] = "layer_deep.png";
}  // namespace model_file

/// Summary statistics of a model, as stored in model.json.
struct ModelStatistics {
  std::size_t cells = 0, valid_cells = 0;
  std::size_t no_skin = 0, no_bone = 0, undercut = 0, grazing = 0, truncated = 0;
  std::size_t base_cavity = 0;  ///< valid cells whose base is an air cavity's edge (kBaseCavity)
  std::size_t base_tissue = 0;  ///< valid cells based on deeper tissue, depth interpolated (kBaseTissue)
  std::size_t eye = 0;          ///< cells on the eye (kEye, not operable)
  double thickness_mean_mm = 0, thickness_median_mm = 0, thickness_p5_mm = 0, thickness_p95_mm = 0;
  double thickness_normal_median_mm = 0;
  double face_theta_deg = 0;      ///< theta of the most prominent feature (the nose)
  double face_z_mm = 0;           ///< its z
  double forehead_thickness_mm = 0;  ///< median over theta in [-15, 15] deg, 30..60 mm above it
  double r_skin_median_mm = 0;
  /// Tissue layers along the ray (zero where not measured): cells with measured layers, cells
  /// with no fat seen or fat in several bands, and medians over the measured cells.
  std::size_t layer_cells = 0, no_fat = 0, several_fat_bands = 0;
  double skin_layer_median_mm = 0, fat_median_mm = 0, deep_median_mm = 0;
};

/// A mesh as model.json describes it.
struct MeshSummary {
  std::int64_t vertices = 0, faces = 0;
  double area_mm2 = 0;
  bool closed = false;
};

/// model.json. The source, segmentation and thickness objects differ between volume- and
/// scan-built models and are kept as JSON text.
struct ModelInfo {
  int format_version = kModelFormatVersion;
  std::string created_by = "caps 0.1.0";
  CylinderAxis axis;  ///< LPS mm
  CylinderGrid grid;
  std::string source_json = "{}";        ///< "source": kind ("volume" | "scan"), path, format, ...
  std::string segmentation_json = "{}";  ///< "segmentation": methods and thresholds
  std::string thickness_json = "{}";     ///< "thickness": kind and how it was measured
  ModelStatistics stats;
  bool has_color = false;  ///< the directory holds model_file::kColor
  bool has_layers = false;  ///< the directory holds the tissue layer maps (model_file::kThicknessSkin...)
  MeshSummary skin, bone;
  /// The model's identity: a hash of its maps (content_hash()), so that a plan made on it can
  /// tell a copy of this model from another one. Empty for models written before it existed.
  std::string content_hash;
  std::vector<std::string> warnings;  ///< what building the model warned about
  /// "landmarks": the anatomical landmarks found on the skin (surface/landmarks.hpp), as JSON
  /// text; empty for a model without them (written before they existed).
  std::string landmarks_json;
  /// "features": the feature lines found on the skin (surface/feature_lines.hpp), as JSON text;
  /// empty for a model without them.
  std::string features_json;

  /// source.kind; "volume" if absent.
  std::string source_kind() const;
  /// thickness.kind ("measured", "approximate", "constant"); "" if absent.
  std::string thickness_kind() const;
};

/// "fnv1a64:<16 hex digits>" over the grid and the r_skin, r_bone, thickness and validity maps'
/// bytes: equal for copies of one model, different for models of other data or settings.
std::string content_hash(const CylindricalMaps& maps);

/// model.json's text for `info`, pretty-printed. Throws InvalidInput if one of the *_json fields
/// is not valid JSON.
std::string model_json_text(const ModelInfo& info);

/// Reads and checks model.json of a model directory: format, version, that every file it names
/// exists, and a usable axis and grid. Throws IoError (no directory, no model.json) or
/// InvalidInput (not JSON, another format or version, a missing file, an unusable grid).
ModelInfo read_model_info(const std::filesystem::path& dir);

/// model.json of a model directory as JSON text (pretty-printed), after the checks of
/// read_model_info().
std::string read_model_json(const std::filesystem::path& dir);

/// The maps of a model directory on `info`'s axis and grid (with the tissue layers where
/// info.has_layers); measured_skin / measured_bone are derived from the validity flags. Throws as
/// read_map_nrrd().
CylindricalMaps read_model_maps(const std::filesystem::path& dir, const ModelInfo& info);

/// The model's colour image (n_theta × n_z, superior on top), or an empty image if it has none.
/// Throws IoError if it cannot be read, InvalidInput if its size is not the grid's.
RgbImage read_model_color(const std::filesystem::path& dir, const ModelInfo& info);

/// What every model holds, whatever built it (a volume or a surface scan).
struct ModelContent {
  CylindricalMaps maps;
  ModelStatistics stats;
  TriMesh skin;    ///< LPS mm
  TriMesh bone;    ///< LPS mm
  RgbImage color;  ///< n_theta wide, n_z high, superior on top; empty if the source has no colour
};

/// Where a model came from, as model.json and the pictures tell it.
struct ModelProvenance {
  std::string source_json;        ///< model.json "source" object, as JSON text
  std::string segmentation_json;  ///< model.json "segmentation" object, as JSON text
  std::string thickness_json;     ///< model.json "thickness" object, as JSON text
  std::string name;               ///< the source's name, shown in the pictures' titles
  std::string credit;             ///< a credit line drawn on the pictures (may be empty)
};

/// Writes a model directory (format 1, docs/model-format.md) atomically; write_model() and the
/// scan importer both use it. An existing `dir` is replaced only with `force`; otherwise
/// InvalidInput (also for a colour image that is not n_theta × n_z or provenance that is not JSON).
/// Progress goes to `reporter`, and its warnings so far are written into model.json.
void write_model_directory(const ModelContent& model, const ModelProvenance& provenance,
                           const std::filesystem::path& dir, bool force,
                           Reporter* reporter = nullptr);

/// Replaces model.json's "landmarks" object of the model directory `dir` by `landmarks_json`
/// (JSON text) and rewrites model.json atomically; nothing else changes. Throws as
/// read_model_info(), InvalidInput for text that is not a JSON object.
void write_model_landmarks(const std::filesystem::path& dir, const std::string& landmarks_json);

/// Replaces model.json's "features" object (the feature lines, JSON text) as
/// write_model_landmarks() does the landmarks; nothing else changes.
void write_model_features(const std::filesystem::path& dir, const std::string& features_json);

/// A few human-readable lines summarising a model directory.
std::string model_summary(const std::filesystem::path& dir);

}  // namespace caps

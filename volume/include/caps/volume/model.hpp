#pragma once
/// @brief The patient model built from a CT or MR volume, and its model directory (format 1).
///
/// A model directory holds model.json (units, axis, grid, source, thresholds, statistics) and the
/// files it names: r_skin / r_bone / thickness / thickness_normal / validity as float32 NRRD maps
/// over (theta, z), thickness.png, skin.png, skin.ply and bone.ply. docs/model-format.md is the
/// reference.

#include <filesystem>
#include <optional>
#include <string>

#include "caps/core/reporter.hpp"
#include "caps/core/mesh.hpp"
#include "caps/volume/cylindrical_map.hpp"
#include "caps/volume/image_io.hpp"
#include "caps/volume/segment.hpp"
#include "caps/volume/volume.hpp"

namespace caps {

inline constexpr int kModelFormatVersion = 1;

struct ModelOptions {
  SegmentOptions segment;
  MapOptions maps;
  std::optional<CylinderAxis> axis;  ///< overrides the fitted axis
  int smoothing_iterations = 10;     ///< Taubin iterations on skin.ply and bone.ply
  double decimate_fraction = 1.0;    ///< keep this fraction of the mesh faces (1 = all)
};

/// Summary statistics of a model, as stored in model.json.
struct ModelStatistics {
  std::size_t cells = 0, valid_cells = 0;
  std::size_t no_skin = 0, no_bone = 0, undercut = 0, grazing = 0, truncated = 0;
  double thickness_mean_mm = 0, thickness_median_mm = 0, thickness_p5_mm = 0, thickness_p95_mm = 0;
  double thickness_normal_median_mm = 0;
  double face_theta_deg = 0;      ///< theta of the most prominent feature (the nose)
  double face_z_mm = 0;           ///< its z
  double forehead_thickness_mm = 0;  ///< median over theta in [-15, 15] deg, 30..60 mm above it
  double r_skin_median_mm = 0;
};

/// Everything built from one volume.
struct VolumeModel {
  Segmentation segmentation;
  CylindricalMaps maps;
  ModelStatistics stats;
  TriMesh skin, bone;
  std::string source;
  std::string source_format;
  Modality modality = Modality::Unknown;
  Eigen::Vector3i source_dims{0, 0, 0};
  Eigen::Vector3d source_spacing_mm{0, 0, 0};
  std::vector<std::string> notes;
};

/// Segments the volume, fits the axis, measures the maps, extracts the surfaces.
VolumeModel build_volume_model(const Volume& v, const ModelOptions& options = {},
                               Reporter* reporter = nullptr);

/// Statistics of the maps (done by build_volume_model; exposed for tests and other sources).
ModelStatistics model_statistics(const CylindricalMaps& maps);

/// Writes the model directory atomically (built under a temporary name, then renamed).
/// An existing `dir` is replaced only with `force`; otherwise InvalidInput.
void write_model(const VolumeModel& model, const std::filesystem::path& dir, bool force,
                 Reporter* reporter = nullptr);

/// What a model directory holds, whatever built it (a volume or a surface scan). The pointers
/// are not owned and must outlive the call to write_model_directory().
struct ModelDirectoryContents {
  const CylindricalMaps* maps = nullptr;   ///< required
  const ModelStatistics* stats = nullptr;  ///< required
  const TriMesh* skin = nullptr;           ///< required, LPS mm
  const TriMesh* bone = nullptr;           ///< required, LPS mm
  const RgbImage* color = nullptr;  ///< optional skin colour, n_theta wide, n_z high, superior on top
  std::string source_json;          ///< model.json "source" object, as JSON text
  std::string segmentation_json;    ///< model.json "segmentation" object, as JSON text
  std::string thickness_json;       ///< model.json "thickness" object, as JSON text
  std::string name;                 ///< the source's name, shown in the pictures' titles
  std::string credit;               ///< a credit line drawn on the pictures (may be empty)
};

/// Writes a model directory (format 1, docs/model-format.md) atomically; write_model() and the
/// scan importer both use it. An existing `dir` is replaced only with `force`; otherwise
/// InvalidInput.
void write_model_directory(const ModelDirectoryContents& contents, const std::filesystem::path& dir,
                           bool force, Reporter* reporter = nullptr);

/// Reads model.json of a model directory and returns it as JSON text (pretty-printed), after
/// checking the format version and that the files it names exist.
std::string read_model_json(const std::filesystem::path& dir);

/// A few human-readable lines summarising a model directory.
std::string model_summary(const std::filesystem::path& dir);

}  // namespace caps

#pragma once
/// @brief The patient model built from a CT or MR volume, written as a model directory
/// (model_dir.hpp, docs/model-format.md).

#include <filesystem>
#include <optional>
#include <string>

#include "caps/core/reporter.hpp"
#include "caps/core/mesh.hpp"
#include "caps/volume/cylindrical_map.hpp"
#include "caps/volume/metal.hpp"
#include "caps/volume/model_dir.hpp"
#include "caps/volume/segment.hpp"
#include "caps/volume/volume.hpp"

namespace caps {

struct ModelOptions {
  SegmentOptions segment;
  MapOptions maps;
  std::optional<CylinderAxis> axis;  ///< overrides the fitted axis
  int smoothing_iterations = 10;     ///< Taubin iterations on skin.ply and bone.ply
  double decimate_fraction = 1.0;    ///< keep this fraction of the mesh faces (1 = all)
  /// A volume that is not a CT whose head holds less than this (ml) is refused as skull-stripped
  /// (brain extraction keeps the brain, 1.1-1.5 l; an adult head, even cut at the chin, holds
  /// well over 2.5 l); 0: no check (a small child's head).
  double min_head_ml = 2000.0;
  /// false: the maps only, no skin.ply and bone.ply surfaces (a trial of an axis, whose maps
  /// are looked at and thrown away: the head's pose, docs/landmarks.md).
  bool surfaces = true;
};

/// Everything built from one volume (the ModelContent, without colour, and how it was made).
struct VolumeModel : ModelContent {
  Segmentation segmentation;
  std::string source;
  std::string source_format;
  Modality modality = Modality::Unknown;
  Eigen::Vector3i source_dims{0, 0, 0};
  Eigen::Vector3d source_spacing_mm{0, 0, 0};
  std::vector<std::string> notes;
  LayerOptions layer_options;  ///< how the tissue layers were measured (model.json)
  BoneOptions bone_options;    ///< how the base (bone, cavity) was found (model.json)
  double bone_cap_mm = MapOptions{}.bone_cap_mm;  ///< the bone cap used (model.json)
  /// The metal found (model.json segmentation.metal); maps.metal marks its cells.
  MetalRegion metal;
  /// For a local chart (a model whose axis faces one region of the skin, surface/chart.hpp):
  /// model.json's source.chart object as JSON text; empty for a whole-head model.
  std::string chart_json;
  /// For a head whose axis was tilted with it (the head's pitch, docs/landmarks.md): model.json's
  /// source.pose object as JSON text; empty when the axis is the scanner's or was given.
  std::string pose_json;
};

/// Segments the volume, fits the axis, measures the maps, extracts the surfaces.
VolumeModel build_volume_model(const Volume& v, const ModelOptions& options = {},
                               Reporter* reporter = nullptr);

/// Statistics of the maps (done by build_volume_model; exposed for tests and other sources).
ModelStatistics model_statistics(const CylindricalMaps& maps);

/// The cells maps.metal marks: how many, the rows (k) and z (mm) they span.
struct MetalCells {
  std::size_t count = 0;
  int row_first = 0, row_last = -1;
  double z_min_mm = 0, z_max_mm = 0;
};
MetalCells metal_cells(const CylindricalMaps& maps);

/// Writes the model directory atomically (built under a temporary name, then renamed).
/// An existing `dir` is replaced only with `force`; otherwise InvalidInput.
void write_model(const VolumeModel& model, const std::filesystem::path& dir, bool force,
                 Reporter* reporter = nullptr);

}  // namespace caps

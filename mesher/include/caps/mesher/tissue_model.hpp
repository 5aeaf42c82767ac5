#pragma once
/// @brief The whole-face tissue model: the patient's soft tissue between skin and bone of the
/// face and scalp as linear tetrahedra, made once per patient from the CT's segmentation
/// (OpenVDB level sets of skin and bone, CGAL's 3-D mesher for labelled images) and kept in the
/// model directory (tissue.vtu, skin.vdb, bone.vdb, tissue.json; docs/model-format.md).
/// docs/mesher.md, "The whole-face tissue model", says what is in it and how it is sized.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "caps/core/reporter.hpp"
#include "caps/volume/cylindrical_map.hpp"
#include "caps/volume/distance_field.hpp"
#include "caps/volume/model_dir.hpp"
#include "caps/volume/segment.hpp"

namespace caps::mesher {

/// The files of the tissue model in a model directory.
namespace tissue_file {
inline constexpr char kMesh[] = "tissue.vtu";
inline constexpr char kJson[] = "tissue.json";
inline constexpr char kSkinLevelSet[] = "skin.vdb";
inline constexpr char kBoneLevelSet[] = "bone.vdb";
}  // namespace tissue_file

/// Where a node lies (OR-ed bits of TissueModel::node_flags; 0 = inside the tissue).
enum TissueNodeFlag : std::uint8_t {
  kTissueOnSkin = 1,         ///< on the skin (|phi_skin| within the tolerance)
  kTissueOnBone = 2,         ///< on the bone (|phi_bone| within the tolerance)
  kTissueFieldOfView = 4,    ///< where the CT's field of view cut the tissue (first/last slice,
                             ///< grid border)
  kTissueOtherBoundary = 8,  ///< on another boundary: an air cavity (sinus, nasal cavity,
                             ///< airway, mouth) or the depth limit
};

/// The layers of the soft tissue, in the order of TissueModel::layer_fraction's columns.
enum class TissueLayer : int { Dermis = 0, Fat = 1, Deep = 2 };
/// "dermis", "fat", "deep".
const char* tissue_layer_name(TissueLayer layer);

/// How the model is made. Sizes in mm.
struct TissueModelOptions {
  /// Tissue deeper than this below the skin (Euclidean, from the skin envelope) is left out:
  /// the brain and the deep neck are not in the model; the globes and the cheek's deep fat are.
  double depth_limit_mm = 30.0;
  double face_size_mm = 1.6;   ///< boundary facets on the face (|theta| <= face_half_angle_deg)
  double scalp_size_mm = 4.0;  ///< boundary facets elsewhere (scalp, neck, behind the ears)
  /// The face: within this angle of the front about the model's axis (in front of the ears),
  /// blending into the scalp's sizes over the next face_blend_deg.
  double face_half_angle_deg = 75.0;
  double face_blend_deg = 20.0;
  /// Tetrahedra: 1.5 x the facet size at the skin, growing by this many mm per mm of depth.
  double cell_growth = 0.3;
  double facet_distance_fraction = 0.25;  ///< the surface's allowed deviation, x the facet size
  double band_mm = 6.0;                   ///< the bone level set's band and the skin's outside band
  /// The level sets' voxel; 0 = the working grid's smallest spacing.
  double level_set_voxel_mm = 0.0;
  /// Pieces of tissue smaller than this (ml) are left out (noise, a strand cut from the rest).
  double min_component_ml = 0.5;
  /// Mesh_3's sliver exudation after the refinement, for at most this long (s; 0: none). No
  /// Lloyd, ODT or perturbation.
  double exude_seconds = 3.0;
};

/// The level sets the model is made from (negative inside the skin / inside the bone).
struct TissueLevelSets {
  SignedDistanceField skin, bone;
};

/// The volumetric model. Frame: patient LPS mm.
struct TissueModel {
  Eigen::MatrixX3d nodes;                ///< #nodes x 3, LPS mm
  Eigen::MatrixX4i tets;                 ///< corner ids; positive volume:
                                         ///< (x1-x0)x(x2-x0).(x3-x0) > 0
  Eigen::MatrixX3f layer_fraction;       ///< per tet: volume fractions of dermis, fat, deep (sum 1)
  std::vector<std::uint8_t> node_flags;  ///< per node, TissueNodeFlag bits

  // Provenance (tissue.json).
  TissueModelOptions options;
  Eigen::Vector3d label_voxel_mm{0, 0, 0};  ///< the label image's voxel (the working grid's)
  double level_set_voxel_mm = 0;
  double volume_ml = 0;                   ///< sum of the tets' volumes
  double layer_volume_ml[3] = {0, 0, 0};  ///< dermis, fat, deep (fractions x volumes)
  double seconds_level_sets = 0, seconds_labels = 0, seconds_mesh = 0, seconds_layers = 0,
         seconds_total = 0;
  /// Share of the layer samples that fell back to the model's median layer thicknesses (their
  /// cylindrical cell has no measured thickness, or lies outside the grid).
  double layer_fallback_fraction = 0;
  std::string source;  ///< the CT it was made from
  std::string method;  ///< one line: how it was made
  std::vector<std::string> warnings;

  Eigen::Index n_nodes() const { return nodes.rows(); }
  Eigen::Index n_tets() const { return tets.rows(); }
  /// Per tet: the layer with the largest fraction (TissueLayer as int).
  std::vector<int> dominant_layer() const;
  /// Number of nodes with every bit of `flag` set.
  std::size_t count_nodes(std::uint8_t flag) const;
};

/// The level sets of the skin envelope and of the bone of a segmentation (from its masks on the
/// working grid; SignedDistanceField::from_mask). The skin's band reaches 16 mm
/// inside (the layers are found by depth below it; deeper, by the voxels' distance transform).
/// Throws InvalidInput for empty masks.
TissueLevelSets tissue_level_sets(const Segmentation& seg, const TissueModelOptions& options = {});

/// Builds the model: the soft tissue (inside the skin envelope, not bone, above the skin
/// threshold: the air cavities are out, within options.depth_limit_mm of the skin, in pieces
/// that reach the skin) as a label image on the working grid, meshed by CGAL Mesh_3 with sizes
/// graded from the face to the scalp and with depth; each tet's layer fractions from 12
/// points' depths below the skin against the maps' measured layer thicknesses (along the normal;
/// the model's medians where a cell has none, said in the warnings), the nodes' flags from the
/// level sets. `maps`/`stats` are the model's (their axis says where the face is).
/// Throws InvalidInput when there is no soft tissue.
TissueModel build_tissue_model(const Segmentation& seg, const CylindricalMaps& maps,
                               const ModelStatistics& stats, const TissueLevelSets& level_sets,
                               const TissueModelOptions& options = {},
                               Reporter* reporter = nullptr);

/// Writes tissue.vtu (VTK XML unstructured grid, ASCII: linear tets (type 10), cell data
/// layer_fraction and dominant_layer, point data node_flags), skin.vdb, bone.vdb and tissue.json
/// into the model directory `dir`, each file atomically. Throws IoError.
void write_tissue_model(const std::filesystem::path& dir, const TissueModel& model,
                        const TissueLevelSets& level_sets);

/// True when `dir` holds a tissue model (tissue.vtu).
bool has_tissue_model(const std::filesystem::path& dir);

/// Reads tissue.vtu (and tissue.json's provenance) back. Throws InvalidInput "the model has no
/// whole-face tissue model: run `caps model tissue MODEL`" when it is absent, InvalidInput for a
/// file this writer did not write or that is damaged (sizes bounded by the file's length; ids,
/// orientation and fractions checked).
TissueModel read_tissue_model(const std::filesystem::path& dir);

/// The bone's / skin's level set of a model directory (bone.vdb / skin.vdb). Throws as
/// read_tissue_model() when absent, InvalidInput when damaged.
SignedDistanceField read_bone_level_set(const std::filesystem::path& dir);
SignedDistanceField read_skin_level_set(const std::filesystem::path& dir);

/// Signed volume of a tet (mm^3): (x1-x0)x(x2-x0).(x3-x0) / 6.
double tet_volume(const Eigen::MatrixX3d& nodes, const Eigen::Vector4i& tet);

}  // namespace caps::mesher

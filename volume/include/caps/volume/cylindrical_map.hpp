#pragma once
/// @brief Cylindrical range images of skin and bone (the Cyberware-style patient model) and the
/// soft-tissue thickness map, measured in a CT or MR volume.
///
/// Coordinates: an axis through the head (unit `direction`, superior), `front` perpendicular to it
/// (anterior). theta = 0 at the front, increasing towards the patient's left (right-handed about
/// the superior axis), in [-180, 180) degrees so the seam is at the back of the head. z is the
/// signed distance along the axis from `origin_lps` (mm); r the distance from the axis (mm).
/// Images are stored theta-fastest: value(j, k) at theta_j = theta0 + j dtheta, z_k = z0 + k dz.

#include <Eigen/Geometry>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "caps/core/reporter.hpp"
#include "caps/volume/metal.hpp"
#include "caps/volume/segment.hpp"
#include "caps/volume/volume.hpp"

namespace caps {

/// The cylinder's axis and angular origin.
struct CylinderAxis {
  Eigen::Vector3d origin_lps{0, 0, 0};  ///< the point of the axis where z = 0
  Eigen::Vector3d direction{0, 0, 1};   ///< unit, towards superior
  Eigen::Vector3d front{0, -1, 0};      ///< unit, perpendicular to direction: theta = 0

  /// Unit vector towards theta = +90 degrees (the patient's left): direction x front.
  Eigen::Vector3d left() const { return direction.cross(front); }
  /// Unit ray direction at theta (radians).
  Eigen::Vector3d ray(double theta_rad) const;
  /// (theta [rad], z [mm], r [mm]) to LPS mm.
  Eigen::Vector3d to_lps(double theta_rad, double z_mm, double r_mm) const;
  /// LPS mm to (theta [rad] in [-pi, pi), z [mm], r [mm]).
  Eigen::Vector3d to_cylindrical(const Eigen::Vector3d& p) const;
};

/// The (theta, z) sampling grid.
struct CylinderGrid {
  int n_theta = 512;
  int n_z = 256;
  double theta0_deg = -180.0;
  double z0_mm = 0.0;
  double dz_mm = 1.0;
  double dtheta_deg() const { return 360.0 / n_theta; }
  double theta_deg(int j) const { return theta0_deg + j * dtheta_deg(); }
  double z_mm(int k) const { return z0_mm + k * dz_mm; }
  std::size_t size() const { return static_cast<std::size_t>(n_theta) * n_z; }
  std::size_t index(int j, int k) const { return static_cast<std::size_t>(k) * n_theta + j; }
};

/// Why a cell is not valid, and which base a valid cell has; a cell's flags are OR-ed. A cell is
/// valid when none of kInvalidFlags is set (0: valid, over bone).
enum CellFlag : std::uint8_t {
  kNoSkin = 1,     ///< the ray never meets skin (above the vertex, below the neck cut)
  kNoBone = 2,     ///< no bone within MapOptions::bone_cap_mm under the skin (nose, lips, neck)
  kUndercut = 4,   ///< the ray crosses the skin more than once (ears, under the nose or chin)
  kGrazing = 8,    ///< the ray meets the skin at a grazing angle (near the vertex)
  /// The head touches the edge of the scanned volume along this ray; or (CT with metal) the
  /// ray's skin or tissue lies in the slices whose metal streaks were removed
  /// (CylindricalMaps::metal, model.json segmentation.metal): the scan does not show it.
  kTruncated = 16,
  /// Valid, with no bone under the skin: the base is the soft tissue's deep boundary on an air
  /// cavity (nasal cavity, mouth, sinus) and carries no support (free; docs/volume.md).
  kBaseCavity = 32,
  /// The eye: the skin lies on the globe (the eyelids over it), seen in CT as a run of soft
  /// tissue at least kGlobeRunMm deep under the skin that ends on the orbit's fat; not operable
  /// (docs/volume.md).
  kEye = 64,
  /// Valid, with neither bone nor an air cavity within MapOptions::bone_cap_mm: the soft tissue
  /// goes on deeper (the cheek over the buccal fat, a skull defect's cover). Its base lies at the
  /// depth interpolated from the measured bases around (at most BoneOptions::tissue_reach_mm
  /// away) and carries no support (free; docs/volume.md).
  kBaseTissue = 128,
};

/// The flags that make a cell invalid (every flag but kBaseCavity and kBaseTissue, which name
/// valid bases).
inline constexpr std::uint8_t kInvalidFlags =
    kNoSkin | kNoBone | kUndercut | kGrazing | kTruncated | kEye;

/// The eye (kEye): a ray over the globe meets kGlobeRunMm to kGlobeMaxRunMm of soft tissue (no
/// fat, bone or air) under the skin before a band of the orbit's fat at least kOrbitFatMm thick.
/// The globe is 22-26 mm across and the lids over it 1-3 mm; elsewhere on the face subcutaneous
/// fat, bone or air comes within 12 mm of the skin, and the muscles of the neck that reach fat
/// only deeper than the globe are not taken for it (docs/volume.md, "The eye: not operable").
inline constexpr double kGlobeRunMm = 15.0;
inline constexpr double kGlobeMaxRunMm = 29.0;
inline constexpr double kOrbitFatMm = 2.0;
/// Cells flagged kEye form the eye only as a patch of at least this skin area (mm2); the patch is
/// then widened by kEyeMarginMm on the skin (the lids' margins, rays tangent to the globe).
inline constexpr double kEyeMinAreaMm2 = 100.0;
inline constexpr double kEyeMarginMm = 3.0;

/// True when `flags` (CellFlag, OR-ed) leave the cell valid: measured skin and thickness, over
/// bone, (kBaseCavity) over an air cavity or (kBaseTissue) on deeper tissue.
constexpr bool flags_valid(std::uint8_t flags) { return (flags & kInvalidFlags) == 0; }

/// True when the cell is invalid only because the cylindrical image cannot hold its skin
/// (undercut or grazing, and nothing worse: not the eye, not beyond the scan), which a local
/// chart facing that skin can (surface/chart.hpp).
constexpr bool flags_chart_would_hold(std::uint8_t flags) {
  return (flags & (kUndercut | kGrazing)) && !(flags & (kNoSkin | kTruncated | kEye));
}

/// Short names of the flags, e.g. "no_bone|undercut", "base_cavity"; "valid" for 0.
std::string describe_flags(std::uint8_t flags);

/// For a plan on an invalid cell: whether the place is not operable (outside the scan: no_skin,
/// truncated), the model cannot represent it yet (undercut, grazing) or no base was found
/// (no_bone), with the flags' names and what to do; a sentence that follows "the point at ...".
/// "" for valid flags.
std::string invalid_flags_advice(std::uint8_t flags);

/// Why a cell's tissue layers (skin, fat, deep) are not measured; OR-ed, 0 means measured.
enum LayerFlag : std::uint8_t {
  kLayerNoThickness = 1,   ///< the cell has no measured thickness (no skin or no bone)
  kLayerNoFat = 2,         ///< no subcutaneous fat seen: fat 0, skin and deep not told apart
  kLayerSeveralBands = 4,  ///< fat in several bands separated by soft tissue
  kLayerNoContrast = 8,    ///< the modality shows no fat contrast that caps uses (MR, unknown)
  kLayerThinSkin = 16,     ///< the profile never rises above the fat level between the skin's
                           ///< ramp and the fat: the dermis is thinner than the partial-volume
                           ///< blur along the ray, so the skin/fat interface is not resolved
};

/// Short names of the layer flags, e.g. "no_fat".
std::string describe_layer_flags(std::uint8_t flags);

/// How the soft tissue between skin and bone is split into skin (dermis), subcutaneous fat and
/// deep tissue (muscle, fascia, galea) along each ray, in CT. docs/volume.md says how the
/// defaults were measured.
struct LayerOptions {
  bool measure = true;  ///< measure the layers (CT only; other modalities get kLayerNoContrast)
  /// The level halfway between fat (about -100 HU) and soft tissue (about +40 HU): samples below
  /// it are fat, and the interfaces are where the profile crosses it (sub-voxel).
  double fat_level_hu = -30.0;
  double merge_gap_mm = 1.5;  ///< fat bands closer than this are one band (septa, vessels)
  double min_band_mm = 0.5;   ///< narrower dips below the level are noise, not fat
};

/// How bone is found along each ray (CT). docs/volume.md says how the floor was chosen.
enum class BoneMethod {
  /// The first bone of the segmentation's mask (SegmentOptions::bone_threshold, 250 HU for CT)
  /// inward from the skin: misses thin facial bone whose partial-volume peak is below it.
  Threshold,
  /// The first peak of the full-resolution profile at least BoneOptions::floor_hu above the
  /// ray's own soft-tissue level, confirmed by its lateral neighbours (not a noise voxel); the
  /// edge is then placed at half maximum between the soft tissue and that peak.
  Edge,
};

/// "threshold" / "edge".
const char* bone_method_name(BoneMethod method);
/// Parses "threshold" / "edge"; throws InvalidInput otherwise.
BoneMethod parse_bone_method(const std::string& name);

/// Where the soft tissue's base is found along each ray.
struct BoneOptions {
  BoneMethod method = BoneMethod::Edge;
  /// Edge: a peak this far above the ray's soft-tissue level (HU) is bone. 150 HU: ten times
  /// the soft-tissue noise of a head CT (about 15 HU), above cartilage (about +100 HU over soft
  /// tissue) and below the partial-volume peaks of the thin facial bones (about +230 HU).
  double floor_hu = 150.0;
  /// Where no bone lies within MapOptions::bone_cap_mm but the soft tissue ends on an air cavity
  /// (nasal cavity, mouth, a sinus without a visible wall), the base is that boundary
  /// (kBaseCavity); otherwise such cells are kNoBone.
  bool cavity_base = true;
  /// CT: a cell with neither bone nor a cavity within the cap (kNoBone and nothing else) at most
  /// this far (mm, over the skin) from a cell with a measured base is kBaseTissue, its depth
  /// interpolated from the measured ones; 0 leaves every such cell kNoBone. The interpolation
  /// is not trusted farther from any measurement (the default's measurement: docs/volume.md,
  /// "the tissue base").
  double tissue_reach_mm = 15.0;
};

/// A ray that re-enters the skin after an air gap of at least this length (mm) is kUndercut.
inline constexpr double kUndercutMinGapMm = 2.0;

struct MapOptions {
  int n_theta = 512;
  int n_z = 256;
  /// No bone deeper than this under the skin, along the ray -> kNoBone. 50 mm: the ramus under
  /// the masseter lies 41-44 mm along the head's oblique rays at the lateral cheek (14 mm along
  /// the normal); the orbit, where a deeper cap would find the orbit's floor, is kEye.
  double bone_cap_mm = 50.0;
  double grazing_deg = 70.0;     ///< ray-to-normal angle beyond which a cell is kGrazing
  BoneOptions bone;
  LayerOptions layers;
  /// The z range of the grid (mm along the axis); by default the head's extent.
  std::optional<double> z_min_mm, z_max_mm;
  /// Metal found in the CT (detect_metal(); the volume given is the one repaired by
  /// repair_metal_slices()): cells whose skin or tissue lies in its slabs are marked kTruncated,
  /// not measured, and filled.
  MetalRegion metal;
};

/// The maps. Images hold grid.size() values, theta fastest. Lengths in mm.
/// r_skin: outermost skin crossing (sub-voxel, half-maximum edge); r_bone: first bone crossing
/// inward from the skin (kBaseCavity cells: the tissue/air edge of the cavity under it;
/// kBaseTissue cells: interpolated from the measured bases around);
/// thickness = r_skin - r_bone (radial, what the extruder uses);
/// thickness_normal: distance from the skin point to the nearest bone (how clinicians measure).
/// Invalid cells are filled (see docs/model-format.md): r_skin and thickness by harmonic
/// interpolation from valid neighbours, so every value is finite; `flags` says which are measured.
/// The tissue layers (empty when not measured, has_layers()): thickness_skin from the skin to the
/// top of the subcutaneous fat, thickness_fat, thickness_deep from the fat to the bone, along the
/// ray (summing to thickness) and along the normal (*_normal, summing to thickness_normal);
/// layer_flags / layer_flags_normal (LayerFlag) say where they were measured; elsewhere they are
/// filled from the measured cells' proportions (fat 0 where none was seen).
struct CylindricalMaps {
  CylinderAxis axis;
  CylinderGrid grid;
  std::vector<float> r_skin, r_bone, thickness, thickness_normal;
  std::vector<std::uint8_t> flags;
  std::vector<std::uint8_t> measured_skin;  ///< 1 where r_skin was measured, 0 where filled
  std::vector<std::uint8_t> measured_bone;  ///< 1 where r_bone was measured, 0 where filled
  std::vector<float> thickness_skin, thickness_fat, thickness_deep;
  std::vector<float> thickness_skin_normal, thickness_fat_normal, thickness_deep_normal;
  std::vector<std::uint8_t> layer_flags, layer_flags_normal;
  /// 1 where the cell was marked kTruncated for metal streaks (MapOptions::metal); empty when
  /// no metal was found. Not a file of the model: model.json's segmentation.metal says where.
  std::vector<std::uint8_t> metal;

  bool is_valid(int j, int k) const { return flags_valid(flags[grid.index(j, k)]); }
  bool has_layers() const { return !thickness_skin.empty(); }
  /// Sizes the layer images to grid.size(), all zero, flagged kLayerNoThickness.
  void allocate_layers();
  /// Sizes every image to grid.size(), all zero (nothing measured yet).
  void allocate();
};

/// The fill policy of every model (docs/model-format.md): values where known == 0 are replaced by
/// the solution of Laplace's equation with the known values as boundary conditions, periodic in
/// theta, no-flux at the z ends. `img` and `known` hold grid.size() values, theta fastest.
void harmonic_fill(std::vector<float>& img, const std::vector<std::uint8_t>& known,
                   const CylinderGrid& grid);

/// Sets kGrazing on measured cells (measured_skin) whose ray meets the range surface r_skin more
/// than `limit_deg` from its normal (slopes from central differences where both neighbours were
/// measured, one-sided otherwise). Used by volume and scan models alike.
void flag_grazing(CylindricalMaps& maps, double limit_deg);

/// Fits the axis to the segmented head: parallel to `oriented.direction` (by default patient
/// superior, LPS +z), through the area-weighted centre of the head's cross-sections square to
/// it; front `oriented.front` (by default anterior, LPS -y). A head leaning in the scanner gets
/// its own direction and this centre (app's from-volume).
CylinderAxis fit_axis(const Segmentation& seg, const CylinderAxis& oriented = CylinderAxis{});

/// One profile split into layers: depths (mm) along it, skin + fat + deep = its length.
struct LayerSplit {
  double skin_mm = 0, fat_mm = 0, deep_mm = 0;
  std::uint8_t flags = 0;  ///< LayerFlag
};

/// Splits the soft tissue between the skin (depth 0) and the bone (depth `length_mm`) into
/// layers from the intensity profile `hu(depth_mm)` (CT, HU): the fat is where the profile lies
/// below options.fat_level_hu, past the skin's partial-volume ramp (`ramp_mm`, about one voxel
/// along the profile). `hu` is sampled every `step_mm`; each interface is located where the
/// profile crosses the level, by linear interpolation between the samples and one more
/// interpolation step on `hu` itself (sub-voxel). Bands closer than merge_gap_mm are joined and
/// then bands narrower than min_band_mm dropped; several bands left -> kLayerSeveralBands (skin
/// to the first band's top, fat to the last band's bottom); none -> kLayerNoFat (fat 0, skin =
/// length, deep 0); fat from the skin's ramp on -> kLayerThinSkin (skin 0).
LayerSplit split_layers(const std::function<double(double)>& hu, double length_mm, double step_mm,
                        double ramp_mm, const LayerOptions& options);

/// Fills cells whose layer flag is set from the proportions of measured cells (harmonic_fill of
/// skin / thickness and fat / thickness; fat stays 0 where kLayerNoFat is the only reason) and
/// makes every cell sum to `total`. All images hold grid.size() values.
void fill_layers(std::vector<float>& skin, std::vector<float>& fat, std::vector<float>& deep,
                 const std::vector<std::uint8_t>& layer_flags, const std::vector<float>& total,
                 const CylinderGrid& grid);

/// Casts one ray per grid cell from the axis outward and measures skin and bone, and the tissue
/// layers (options.layers) in CT. `v` is the full-resolution volume `seg` was computed from.
CylindricalMaps cylindrical_maps(const Volume& v, const Segmentation& seg, const CylinderAxis& axis,
                                 const MapOptions& options = {}, Reporter* reporter = nullptr);

}  // namespace caps

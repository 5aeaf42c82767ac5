#pragma once
/// @brief Patient models and volumes as requests and results: `caps model from-volume`,
/// `from-scan`, `info`, `pick`, `export-range`, `color-picture`, `caps volume info` and
/// `caps phantom`.

#include <optional>
#include <string>
#include <vector>

#include "caps/app/fields.hpp"
#include "caps/core/reporter.hpp"
#include "caps/mesher/tissue_model.hpp"
#include "caps/surface/scan_model.hpp"
#include "caps/volume/model.hpp"
#include "caps/volume/phantom.hpp"
#include "caps/volume/read_volume.hpp"

namespace caps::app {

/// What model-building verbs return: the model.json written (warnings included).
struct ModelResult {
  std::string output;
  std::string model_json;  ///< model.json as written
  std::string summary;     ///< the model's summary for reading (model_summary())
  std::vector<std::string> warnings;

  /// The JSON is model.json and, when one was written, the output.
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v.document(r.model_json, {"model_json", "model.json"});
    v.when(!r.output.empty(), [&] { v(r.output, {"output", "the model directory written"}); });
  }
};
std::string to_json(const ModelResult& result);
std::string summary(const ModelResult& result);

// ---- caps model from-volume ---------------------------------------------------------------

struct FromVolumeRequest {
  std::string input, output, series, bone_mask, axis_origin, axis_dir, modality;
  std::optional<double> skin_threshold, bone_threshold;
  int n_theta = MapOptions{}.n_theta, n_z = MapOptions{}.n_z;
  double bone_cap = MapOptions{}.bone_cap_mm;
  std::string bone_method = bone_method_name(BoneOptions{}.method);
  double bone_floor = BoneOptions{}.floor_hu;
  double tissue_reach = BoneOptions{}.tissue_reach_mm;
  double decimate = ModelOptions{}.decimate_fraction;
  double min_head_ml = ModelOptions{}.min_head_ml;
  double mr_scalp = SegmentOptions{}.mr_scalp_mm;
  double fat_level = LayerOptions{}.fat_level_hu;
  double fat_merge_gap = LayerOptions{}.merge_gap_mm;
  double fat_min_band = LayerOptions{}.min_band_mm;
  double max_voxels = kDefaultMaxVoxels, max_bytes = kDefaultMaxBytes;
  bool allow_missing_slices = false, no_layers = false, no_cavity_base = false, force = false;
  bool no_tissue = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.input, {"input", "the volume: a DICOM folder, .nii/.nii.gz, .nrrd/.nhdr, .mha/.mhd or an "
                         "InVesalius .inv3", FieldKind::Positional, "INPUT"});
    v(r.output, {"output", "the model directory to create", FieldKind::Required, "-o,--output"});
    v(r.series, {"series", "DICOM SeriesInstanceUID (default: the largest series)"});
    v(r.allow_missing_slices, {"allow_missing_slices", "DICOM: interpolate across gaps where "
                                                       "slices seem to be missing", FieldKind::Flag});
    v(r.modality, {"modality", "override the modality: CT or MR"});
    v(r.skin_threshold, {"skin_threshold", "tissue/air threshold (default: -400 HU for CT, Otsu "
                                           "for MR)"});
    v(r.bone_threshold, {"bone_threshold", "bone threshold (default: 250 HU for CT)"});
    v(r.bone_mask, {"bone_mask", "bone mask or label volume (non-zero = bone), e.g. for MR"});
    v(r.mr_scalp, {"mr_scalp", "MR without --bone-mask: assumed scalp depth in mm"});
    v(r.axis_origin, {"axis_origin", "a point of the cylinder axis, LPS mm: X,Y,Z"});
    v(r.axis_dir, {"axis_dir", "the axis direction (towards superior), LPS: X,Y,Z"});
    v(r.n_theta, {"n_theta", "cylindrical grid: samples around"});
    v(r.n_z, {"n_z", "cylindrical grid: samples along the axis"});
    v(r.bone_cap, {"bone_cap", "no bone within this depth (mm) marks a cell invalid"});
    v(r.bone_method, {"bone_method", "CT: how bone is found along each ray: edge (a peak "
                                     "--bone-floor above the soft tissue; finds thin facial "
                                     "bone) or threshold (the --bone-threshold mask)"});
    v(r.bone_floor, {"bone_floor", "CT, --bone-method edge: a peak this far (HU) above the "
                                   "soft tissue is bone"});
    v(r.no_cavity_base, {"no_cavity_base", "CT: where no bone lies under the skin, leave the "
                                           "cell no_bone instead of basing it on the air cavity "
                                           "under the tissue", FieldKind::Flag});
    v(r.tissue_reach, {"tissue_reach", "CT: where neither bone nor an air cavity lies under the "
                                       "skin within the cap, base the cell on the deeper tissue "
                                       "(free, its depth interpolated) up to this far (mm) from a "
                                       "measured base; 0: leave it no_bone"});
    v(r.decimate, {"decimate", "fraction of mesh faces to keep (0..1]"});
    v(r.min_head_ml, {"min_head_ml", "an MR whose head holds less (ml) is refused as skull-stripped "
                                     "(brain only); 0: no check, for a small child's whole head"});
    v(r.fat_level, {"fat_level", "tissue layers (CT): HU level halfway between fat and soft "
                                 "tissue; fat lies below it"});
    v(r.fat_merge_gap, {"fat_merge_gap", "tissue layers: fat bands closer than this (mm) are one"});
    v(r.fat_min_band, {"fat_min_band", "tissue layers: narrower dips (mm) are noise, not fat"});
    v(r.no_layers, {"no_layers", "do not measure the tissue layers (skin, fat, deep)",
                    FieldKind::Flag});
    v(r.no_tissue, {"no_tissue", "do not build the whole-face tissue model (tissue.vtu, skin.vdb, "
                                 "bone.vdb; caps model tissue builds it later)", FieldKind::Flag});
    v(r.max_voxels, {"max_voxels", "refuse a volume declaring more voxels (default 2^31)"});
    v(r.max_bytes, {"max_bytes", "refuse a volume needing more bytes of memory (default 8 GiB)"});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

ModelResult run_from_volume(const FromVolumeRequest& request, Reporter* reporter = nullptr);

// ---- caps model chart ----------------------------------------------------------------------

/// A local chart of a volume-built model (surface/chart.hpp): the same CT measured again on a
/// cylinder whose axis faces the skin at one point, for plans where the head's cylinder meets the
/// skin edge-on (the side of the nose) or behind other skin. The point becomes theta 0, z 0 of
/// the chart.
struct ChartRequest {
  std::string model, at, at_xyz, output, series;
  double radius = 60.0;         ///< mm from the chart's axis to the point
  double half_height = 30.0;    ///< mm of the chart's axis on either side of the point
  double normal_radius = 5.0;   ///< mm: the skin's normal is averaged over this radius
  int n_theta = 720, n_z = 200;
  bool force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "a model directory built by caps model from-volume",
                FieldKind::Positional, "MODEL_DIR"});
    v(r.at, {"at", "the point the chart faces: THETA,Z (deg, mm) of the model or a landmark and "
                   "mm to the patient's left and up along the skin: pronasale-8,5"});
    v(r.at_xyz, {"at_xyz", "instead of --at: the point as an LPS point X,Y,Z (mm), taken to the "
                           "skin along the model's ray through it"});
    v(r.output, {"output", "the chart's model directory to create", FieldKind::Required,
                 "-o,--output"});
    v(r.series, {"series", "DICOM: the SeriesInstanceUID the model was built from, if it was not "
                           "the largest"});
    v(r.radius, {"radius", "distance (mm) from the chart's axis to the point: larger sees a "
                           "flatter region more nearly face-on, smaller wraps around a rounder one"});
    v(r.half_height, {"half_height", "the chart spans this far (mm) above and below the point"});
    v(r.normal_radius, {"normal_radius", "the skin's normal at the point is averaged over the "
                                         "skin surface within this distance (mm)"});
    v(r.n_theta, {"n_theta", "the chart's grid: samples around its axis"});
    v(r.n_z, {"n_z", "the chart's grid: samples along its axis"});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

/// Builds the chart from the volume the model names (model.json source.path), with the options
/// the model records (thresholds, bone method and cap, cavity base, layers); model.json's
/// source.chart says where it looks. Throws InvalidInput for a scan-built model or one whose
/// bone came from a separate mask, IoError when the volume is no longer where it was.
ModelResult run_chart(const ChartRequest& request, Reporter* reporter = nullptr);

// ---- caps model from-scan -----------------------------------------------------------------

/// A scan file's colour options (from-scan, register, fuse).
struct ScanTextureFields {
  std::string texture;
  bool flip_v = false;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.texture, {"texture", "colour texture (JPEG or PNG) for the scan's texture coordinates, "
                             "overriding the file's own"});
    v(r.flip_v, {"flip_v", "flip the texture's v coordinate (v' = 1 - v)", FieldKind::Flag});
  }
};

struct FromScanRequest : ScanTextureFields {
  std::string input, output, up = "+y", front = "+z", credit, axis_origin, color;
  std::optional<double> thickness, scale, head_height_mm;
  bool flip_faces = false;
  int n_theta = MapOptions{}.n_theta, n_z = MapOptions{}.n_z;
  // Cylindrical range images (Cyberware style): a sidecar .json, or a grey PNG with these.
  std::optional<double> r_scale, z_scale;
  double r_offset = 0, theta_span = 360;
  bool theta_rows = false, theta_reverse = false, bottom_first = false;
  bool force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.input, {"input", "the scan: .glb/.gltf, .ply, .obj, .vtk, or a cylindrical range image "
                         "(sidecar .json, or a grey PNG with --r-scale and --z-scale)",
                FieldKind::Positional, "INPUT"});
    v(r.output, {"output", "the model directory to create", FieldKind::Required, "-o,--output"});
    v(r.thickness, {"thickness", "constant soft-tissue thickness, mm (required)"});
    ScanTextureFields::fields(r, v);
    v(r.scale, {"scale", "millimetres per file unit (glTF default 1000: metres; other formats "
                         "default 1: mm)"});
    v(r.head_height_mm, {"head_height_mm", "scale the scan so it is this tall along --up (for "
                                           "files in arbitrary units)"});
    v(r.up, {"up", "file direction towards the top of the head: +x -x +y -y +z -z or X,Y,Z"});
    v(r.front, {"front", "file direction the face looks along, perpendicular to --up"});
    v(r.flip_faces, {"flip_faces", "reverse the faces of a file whose normals point into the head",
                     FieldKind::Flag});
    v(r.axis_origin, {"axis_origin", "a point of the cylinder axis, LPS mm: X,Y,Z (default: "
                                     "fitted)"});
    v(r.n_theta, {"n_theta", "cylindrical grid: samples around"});
    v(r.n_z, {"n_z", "cylindrical grid: samples along the axis"});
    v(r.credit, {"credit", "a credit line drawn on the model's pictures (e.g. the scan's licence)"});
    v(r.color, {"color", "cylindrical range image: its colour image (PNG)"});
    v(r.r_scale, {"r_scale", "cylindrical range image: mm per range value"});
    v(r.r_offset, {"r_offset", "cylindrical range image: radius in mm for a range value of 0"});
    v(r.z_scale, {"z_scale", "cylindrical range image: mm between neighbouring z lines"});
    v(r.theta_span, {"theta_span", "cylindrical range image: its extent in theta, degrees"});
    v(r.theta_rows, {"theta_rows", "cylindrical range image: theta runs down the rows (z across)",
                     FieldKind::Flag});
    v(r.theta_reverse, {"theta_reverse", "cylindrical range image: theta decreases along its axis",
                        FieldKind::Flag});
    v(r.bottom_first, {"bottom_first", "cylindrical range image: the first z line is the bottom",
                       FieldKind::Flag});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

ModelResult run_from_scan(const FromScanRequest& request, Reporter* reporter = nullptr);

// ---- caps model info / pick / export-range / color-picture --------------------------------

struct ModelInfoRequest {
  std::string model;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "a model directory", FieldKind::Positional, "MODEL_DIR"});
  }
};

/// The model's model.json and summary (output empty).
ModelResult run_model_info(const ModelInfoRequest& request, Reporter* reporter = nullptr);

struct PickRequest {
  std::string model, ray;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "a model directory", FieldKind::Positional, "MODEL_DIR"});
    v(r.ray, {"ray", "origin and direction, LPS mm: OX,OY,OZ,DX,DY,DZ", FieldKind::Required});
  }
};

struct PickResult {
  bool hit = false;
  Eigen::Vector3d lps{0, 0, 0};
  double theta_deg = 0, z_mm = 0, distance_mm = 0;
  std::string flags;
  bool on_pole_cap = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.hit, {"hit"});
    v.when(r.hit, [&] {
      v(r.lps, {"lps", "the skin point, LPS mm"});
      v(r.theta_deg, {"theta_deg"});
      v(r.z_mm, {"z_mm"});
      v(r.distance_mm, {"distance_mm", "along the ray"});
      v(r.flags, {"flags"});
      v(r.on_pole_cap, {"on_pole_cap"});
    });
  }
};

PickResult run_pick(const PickRequest& request, Reporter* reporter = nullptr);
std::string to_json(const PickResult& result);
std::string summary(const PickResult& result);

struct ExportRangeRequest {
  std::string model, output;
  double r_scale = 0.01;
  bool force = false;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "a model directory", FieldKind::Positional, "MODEL_DIR"});
    v(r.output, {"output", "the folder to create", FieldKind::Required, "-o,--output"});
    v(r.r_scale, {"r_scale", "mm per range value"});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

/// Writes range.png, color.png and range.json; returns the sidecar's path.
struct PathResult {
  std::string output;
  std::vector<std::string> warnings;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.output, {"output", "the file written"});
    v(r.warnings, {"warnings"});
  }
};
std::string to_json(const PathResult& result);
std::string summary(const PathResult& result);

PathResult run_export_range(const ExportRangeRequest& request, Reporter* reporter = nullptr);

struct ColorPictureRequest {
  std::string model, output;
  bool force = false;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "a model directory with color.png", FieldKind::Positional, "MODEL_DIR"});
    v(r.output, {"output", "the PNG to write", FieldKind::Required, "-o,--output"});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

PathResult run_color_picture(const ColorPictureRequest& request, Reporter* reporter = nullptr);

// ---- caps model landmarks -----------------------------------------------------------------

struct LandmarksRequest {
  std::string model;
  bool no_write = false;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "a model directory", FieldKind::Positional, "MODEL_DIR"});
    v(r.no_write, {"no_write", "print the landmarks without writing them into model.json",
                   FieldKind::Flag});
  }
};

/// The anatomical landmarks of a model (surface/landmarks.hpp), as model.json stores them.
struct LandmarksResult {
  std::string model;
  std::string landmarks_json;  ///< model.json's "landmarks" object
  std::string table;           ///< landmarks_table(): one line per landmark
  bool written = false;        ///< model.json was updated
  std::vector<std::string> warnings;

  /// The JSON is model.json's "landmarks" object with the model, written and the warnings.
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v.document(r.landmarks_json, {"landmarks_json", "model.json's \"landmarks\""});
    v(r.model, {"model"});
    v(r.written, {"written", "model.json was updated"});
    v(r.warnings, {"warnings"});
  }
};
/// Finds the model's landmarks and (unless no_write) writes them into its model.json, so a model
/// built before landmarks existed gains them.
LandmarksResult run_model_landmarks(const LandmarksRequest& request, Reporter* reporter = nullptr);
std::string to_json(const LandmarksResult& result);
std::string summary(const LandmarksResult& result);

// ---- caps model features ------------------------------------------------------------------

struct FeaturesRequest {
  std::string model;
  bool no_write = false;
  std::string picture;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "a model directory", FieldKind::Positional, "MODEL_DIR"});
    v(r.no_write, {"no_write", "print the feature lines without writing them into model.json",
                   FieldKind::Flag});
    v(r.picture, {"picture", "also draw the lines and the landmarks on a front view of the "
                             "skin into this PNG (e.g. MODEL_DIR/features.png)"});
  }
};

/// The feature lines on a model's skin (surface/feature_lines.hpp), as model.json stores them.
struct FeaturesResult {
  std::string model;
  std::string features_json;  ///< model.json's "features" object
  std::string table;          ///< feature_lines_table(): one line per feature
  bool written = false;       ///< model.json was updated
  std::string picture;        ///< the PNG drawn, or empty
  std::vector<std::string> warnings;

  /// The JSON is model.json's "features" object with the model, written, picture and warnings.
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v.document(r.features_json, {"features_json", "model.json's \"features\""});
    v(r.model, {"model"});
    v(r.written, {"written", "model.json was updated"});
    v(r.picture, {"picture", "the PNG drawn, or empty"});
    v(r.warnings, {"warnings"});
  }
};
/// Finds the feature lines of a model beside its landmarks (found again if model.json has none)
/// and (unless no_write) writes them into its model.json.
FeaturesResult run_model_features(const FeaturesRequest& request, Reporter* reporter = nullptr);
std::string to_json(const FeaturesResult& result);
std::string summary(const FeaturesResult& result);
// ---- caps model tissue -------------------------------------------------------------------

/// The whole-face tissue model of a volume-built model (mesher/tissue_model.hpp), made again
/// from the CT it was built from, segmented with the options model.json records.
struct TissueRequest {
  std::string model;
  double depth_limit = mesher::TissueModelOptions{}.depth_limit_mm;
  double face_size = mesher::TissueModelOptions{}.face_size_mm;
  double scalp_size = mesher::TissueModelOptions{}.scalp_size_mm;
  bool force = false;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "a model directory built by caps model from-volume",
                FieldKind::Positional, "MODEL_DIR"});
    v(r.depth_limit, {"depth_limit", "leave out soft tissue deeper than this below the skin (mm)"});
    v(r.face_size, {"face_size", "element size on the face's skin and bone (mm)"});
    v(r.scalp_size, {"scalp_size", "element size elsewhere: scalp, neck, behind the ears (mm)"});
    v(r.force, {"force", "replace the model's existing tissue model", FieldKind::Flag});
  }
};

/// What `caps model tissue` made: tissue.json (counts, sizes, times, method, warnings).
struct TissueResult {
  std::string model;
  std::string tissue_json;  ///< tissue.json as written
  std::string summary;      ///< one line: counts, volume, time
  std::vector<std::string> warnings;

  /// The JSON is tissue.json with the model and the warnings.
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v.document(r.tissue_json, {"tissue_json", "tissue.json"});
    v(r.model, {"model"});
    v(r.warnings, {"warnings"});
  }
};
/// Builds the model directory's whole-face tissue model (tissue.vtu, skin.vdb, bone.vdb,
/// tissue.json) from the CT named in its model.json. InvalidInput for a model built from a
/// surface scan, a chart, one whose bone came from a separate mask, or one that has a tissue
/// model already (without force); IoError when the CT is not there any more.
TissueResult run_model_tissue(const TissueRequest& request, Reporter* reporter = nullptr);
std::string to_json(const TissueResult& result);
std::string summary(const TissueResult& result);

// ---- caps model site ----------------------------------------------------------------------

struct SiteRequest {
  std::string model, at;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "a model directory", FieldKind::Positional, "MODEL_DIR"});
    v(r.at, {"at", "the point on the skin: THETA,Z (deg, mm) or a landmark and mm to the "
                   "patient's left and up along the skin: glabella+15,20", FieldKind::Required});
  }
};

/// The skin and the soft tissue at one point of a model (where `caps plan new --at` would put a
/// plan's centre).
struct SiteResult {
  std::string model, at;
  double theta_deg = 0, z_mm = 0;
  Eigen::Vector3d lps{0, 0, 0};          ///< the skin point, LPS mm
  double thickness_mm = 0;               ///< soft tissue along the skin normal (thickness_normal)
  double thickness_radial_mm = 0;        ///< soft tissue along the ray from the axis
  bool has_layers = false;               ///< the model has measured tissue layers
  double skin_mm = 0, fat_mm = 0, deep_mm = 0;  ///< the layers along the normal (has_layers)
  std::string flags;                     ///< describe_flags() of the cells there ("valid")
  std::string doubt;                     ///< why the tissue measured there is implausible (tissue_doubt())
  std::vector<std::string> warnings;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model"});
    v(r.at, {"at"});
    v(r.theta_deg, {"theta_deg"});
    v(r.z_mm, {"z_mm"});
    v(r.lps, {"lps", "the skin point, LPS mm"});
    v(r.thickness_mm, {"thickness_mm", "soft tissue along the skin normal"});
    v(r.thickness_radial_mm, {"thickness_radial_mm", "soft tissue along the ray from the axis"});
    v(r.flags, {"flags"});
    v.when(!r.doubt.empty(), [&] {
      v(r.doubt, {"doubt", "why the tissue measured here is implausible for a layer over bone"});
    });
    v(r.warnings, {"warnings"});
    v.when(r.has_layers, [&] {
      v.group({"layers_mm", "the measured layers along the normal"}, [&] {
        v(r.skin_mm, {"skin"});
        v(r.fat_mm, {"fat"});
        v(r.deep_mm, {"deep"});
      });
    });
  }
};
/// Resolves `at` on the model (a landmark placement as plan new does) and samples its maps there.
SiteResult run_model_site(const SiteRequest& request, Reporter* reporter = nullptr);
std::string to_json(const SiteResult& result);
std::string summary(const SiteResult& result);

// ---- caps volume info ---------------------------------------------------------------------

struct VolumeInfoRequest {
  std::string input, series;
  int volume_index = 0;
  double max_voxels = kDefaultMaxVoxels, max_bytes = kDefaultMaxBytes;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.input, {"input", "a DICOM folder, .nii/.nii.gz, .hdr/.img, .nrrd/.nhdr, .mha/.mhd, .inv3",
                FieldKind::Positional, "INPUT"});
    v(r.series, {"series", "DICOM SeriesInstanceUID"});
    v(r.volume_index, {"volume_index", "NIfTI with several volumes (4-D): the one to read, from 0"});
    v(r.max_voxels, {"max_voxels", "refuse a volume declaring more voxels (default 2^31)"});
    v(r.max_bytes, {"max_bytes", "refuse a volume needing more bytes of memory (default 8 GiB)"});
  }
};

struct VolumeInfoResult {
  std::string json;  ///< geometry (LPS), modality, value range and moments, notes, DICOM series
  std::string text;  ///< the same for reading

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v.document(r.json, {"json"});
  }
};
VolumeInfoResult run_volume_info(const VolumeInfoRequest& request, Reporter* reporter = nullptr);
std::string to_json(const VolumeInfoResult& result);
std::string summary(const VolumeInfoResult& result);

// ---- caps phantom -------------------------------------------------------------------------

struct PhantomRequest {
  std::string output, voxels = "256,256,240", spacing = "1,1,1";
  bool no_holder = false, layered = false, thin_bone = false, face = false, force = false;
  bool metal = false;
  double metal_z = PhantomOptions{}.metal_z_mm;
  double scale = PhantomOptions{}.scale;
  double pitch = 0, yaw = 0, roll = 0;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.output, {"output", "output .nii or .nii.gz", FieldKind::Required, "-o,--output"});
    v(r.voxels, {"voxels", "voxels along L,P,S", FieldKind::Option, {}, "--size"});
    v(r.spacing, {"spacing", "voxel size in mm along L,P,S"});
    v(r.no_holder, {"no_holder", "leave out the head-holder arc", FieldKind::Flag});
    v(r.layered, {"layered", "soft tissue in three layers of known depth: dermis, fat, muscle",
                  FieldKind::Flag});
    v(r.thin_bone, {"thin_bone", "a thin bone plate (0.5-1.5 mm, partial volume) under the right "
                                 "cheek", FieldKind::Flag});
    v(r.face, {"face", "a face of analytic landmarks (brow, nose, lips, chin, eyes, cheeks, "
                       "ears) instead of the plain nose", FieldKind::Flag});
    v(r.metal, {"metal", "a dental metal block in the upper jaw with the streak artefacts it "
                         "makes in the axial slices through it (values clipped to -1024..3071 HU)",
                FieldKind::Flag});
    v(r.metal_z, {"metal_z", "with --metal: the metal's height on the head's axis (mm, -90..60; "
                             "-40 the upper teeth, -68 the chin)"});
    v(r.scale, {"scale", "the head's size: every length of the head times this (0.7..1.3)"});
    v(r.pitch, {"pitch", "the head tilted forward in the scanner, chin towards the chest (deg, "
                         "-45..45)"});
    v(r.yaw, {"yaw", "the head turned towards the patient's left in the scanner (deg, -45..45)"});
    v(r.roll, {"roll", "the head leaning towards the patient's left shoulder in the scanner, the "
                       "vertex towards the left (deg, -45..45; applied before the pitch and yaw)"});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

struct PhantomResult {
  std::string output;
  Eigen::Vector3i dims{0, 0, 0};
  Eigen::Vector3d spacing_mm{0, 0, 0};
  bool head_holder = true;
  bool layered = false;
  bool thin_bone = false;
  bool face = false;
  double scale = 1.0;
  bool metal = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.output, {"output", "the NIfTI file written"});
    v(r.dims, {"dims", "voxels along L,P,S"});
    v(r.spacing_mm, {"spacing_mm"});
    v(r.head_holder, {"head_holder"});
    v(r.layered, {"layered"});
    v(r.thin_bone, {"thin_bone"});
    v(r.face, {"face"});
    v(r.scale, {"scale"});
    v(r.metal, {"metal"});
  }
};
PhantomResult run_phantom(const PhantomRequest& request, Reporter* reporter = nullptr);
std::string to_json(const PhantomResult& result);
std::string summary(const PhantomResult& result);

}  // namespace caps::app

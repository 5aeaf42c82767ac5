#pragma once
/// @brief A surface scan and a CT model of one patient as requests and results:
/// `caps model register` (the scan brought into the model's frame, and where they disagree) and
/// `caps model fuse` (a model with the scan's colour over the CT's depths).

#include <optional>
#include <string>
#include <vector>

#include "caps/app/fields.hpp"
#include "caps/app/model.hpp"
#include "caps/core/reporter.hpp"
#include "caps/surface/fuse.hpp"
#include "caps/surface/register.hpp"

namespace caps::app {

/// The scan file's options and the registration's, shared by register and fuse.
struct ScanRegistrationFields : ScanTextureFields {
  std::optional<double> scan_scale;
  std::string up, front;
  double max_orientation = RegistrationOptions{}.max_orientation_deg;
  bool estimate_scale = RegistrationOptions{}.estimate_scale;
  double voxel = RegistrationOptions{}.voxel_mm;
  double icp_distance = RegistrationOptions{}.icp_final_mm;
  double overlap_distance = RegistrationOptions{}.overlap_mm;
  double max_rms = RegistrationOptions{}.max_rms_mm;
  double max_median = RegistrationOptions{}.max_median_mm;
  double min_overlap = RegistrationOptions{}.min_overlap;
  double max_scale_change = RegistrationOptions{}.max_scale_change;
  bool accept_other_head = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    ScanTextureFields::fields(r, v);
    v(r.scan_scale, {"scan_scale", "millimetres per scan unit (default: mm, cm or m, whichever "
                                   "fits the model's size)"});
    v(r.up, {"up", "the scan file's direction towards the top of the head (+x -x +y -y +z -z or "
                   "X,Y,Z; with --front: only orientations near it are tried)"});
    v(r.front, {"front", "the scan file's direction the face looks along (with --up)"});
    v(r.max_orientation, {"max_orientation", "with --up/--front: the largest rotation away from "
                                             "them tried, degrees"});
    v(r.estimate_scale, {"estimate_scale", "also find a uniform scale (scans in arbitrary units)",
                         FieldKind::Flag});
    v(r.voxel, {"voxel", "sampling of the coarse (feature) alignment, mm"});
    v(r.icp_distance, {"icp_distance", "the last ICP correspondence distance (outlier trim), mm"});
    v(r.overlap_distance, {"overlap_distance", "a scan vertex this close to the skin overlaps "
                                               "it, mm"});
    v(r.max_rms, {"max_rms", "refuse above this RMS distance over the overlap, mm"});
    v(r.max_median, {"max_median", "refuse above this median distance over the scan, mm"});
    v(r.min_overlap, {"min_overlap", "refuse below this fraction of the scan overlapping the "
                                     "skin"});
    v(r.max_scale_change, {"max_scale_change", "with --estimate-scale: refuse when the estimate "
                                               "moves the scale by more than this factor"});
    v(r.accept_other_head, {"accept_other_head", "write the results even when the residual says "
                                                 "the scan is of another head", FieldKind::Flag});
  }
};

// ---- caps model register ------------------------------------------------------------------

struct RegisterRequest : ScanRegistrationFields {
  std::string input, to, output, credit;
  double distance_scale = 5.0;
  bool force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.input, {"input", "the scan: .glb/.gltf, .ply, .obj or .vtk (partial coverage allowed)",
                FieldKind::Positional, "SCAN"});
    v(r.to, {"to", "the model directory whose skin the scan is registered to (skin.ply)",
             FieldKind::Required});
    v(r.output, {"output", "the folder to create: registration.json, distance.ply, distance.png",
                 FieldKind::Required, "-o,--output"});
    ScanRegistrationFields::fields(r, v);
    v(r.distance_scale, {"distance_scale", "top of the distance picture's colour scale, mm"});
    v(r.credit, {"credit", "a credit line drawn on the picture (e.g. the scan's licence)"});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

struct RegisterResult {
  std::string output;
  std::string json;     ///< registration.json as written
  ScanRegistration registration;  ///< without the per-vertex distances
  std::vector<std::string> warnings;

  /// The JSON is registration.json with the output and the warnings.
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v.document(r.json, {"json", "registration.json"});
    v(r.output, {"output", "the folder written"});
    v(r.warnings, {"warnings"});
  }
};

/// Registers the scan to the model's skin and writes registration.json (the 4×4 scan-to-model
/// matrix, LPS mm, scale, residual statistics), distance.ply (the registered scan with a float
/// "distance" vertex property, signed mm, + outside the skin) and distance.png (the scan seen
/// from the front, coloured by |distance| with a colour bar). Throws InvalidInput (nothing
/// written) when the residual says the scan is of another head, unless accept_other_head.
RegisterResult run_register(const RegisterRequest& request, Reporter* reporter = nullptr);
std::string to_json(const RegisterResult& result);
std::string summary(const RegisterResult& result);

/// The 4×4 "scan_to_model" matrix of a registration.json (`caps model register`): scan file
/// units to the model's LPS mm. Throws IoError (unreadable) or InvalidInput (no finite 4×4 matrix).
Eigen::Matrix4d read_registration_matrix(const std::string& path);

// ---- caps model fuse ----------------------------------------------------------------------

struct FuseRequest : ScanRegistrationFields {
  std::string input, to, registration, output, credit;
  bool scan_skin = FuseOptions{}.scan_skin;
  double max_gap = FuseOptions{}.max_gap_mm;
  bool force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.input, {"input", "the scan with its colour: .glb/.gltf, .ply, .obj or .vtk",
                FieldKind::Positional, "SCAN"});
    v(r.to, {"to", "the CT model directory (its depths and layers are kept)", FieldKind::Required});
    v(r.output, {"output", "the fused model directory to create", FieldKind::Required,
                 "-o,--output"});
    v(r.registration, {"registration", "registration.json of `caps model register` (default: "
                                       "register now with the options below)"});
    v(r.scan_skin, {"scan_skin", "take the skin surface from the scan where it covers (default: "
                                 "the CT's skin, the scan's colour only)", FieldKind::Flag});
    v(r.max_gap, {"max_gap", "scan points further than this from the CT's skin are not used, mm"});
    ScanRegistrationFields::fields(r, v);
    v(r.credit, {"credit", "a credit line drawn on the model's pictures (e.g. the scan's licence)"});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

/// Writes a model directory whose colour (and with scan_skin, skin) comes from the registered
/// scan and whose bone, thickness and layers come from the CT model; model.json's source says
/// so ("fused_scan": the scan, the matrix, the cells coloured).
ModelResult run_fuse(const FuseRequest& request, Reporter* reporter = nullptr);

}  // namespace caps::app

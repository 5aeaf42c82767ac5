#pragma once
/// @brief One plan on the patient's CT, scan-built and fused models (`caps compare-models`), and
/// the map of where a constant thickness misleads (`caps model sensitivity`), as requests and
/// results.

#include <string>
#include <vector>

#include "caps/app/fields.hpp"
#include "caps/app/simulation.hpp"
#include "caps/core/reporter.hpp"
#include "caps/study/thickness_sensitivity.hpp"

namespace caps::app {

// ---- caps compare-models ------------------------------------------------------------------

struct CompareModelsRequest {
  std::string model, plan, scan_model, registration, fused_model, output;
  MeshingFields meshing;
  SolverFields solver;
  bool force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "the CT (or MR) model directory the plan was made on: the reference",
                FieldKind::Required});
    v(r.plan, {"plan", "the plan on that model (caps plan new)", FieldKind::Required});
    v(r.scan_model, {"scan_model", "the model built from the surface scan alone (caps model "
                                   "from-scan, constant thickness)"});
    v(r.registration, {"registration", "with --scan-model: registration.json of `caps model "
                                       "register SCAN --to MODEL` (the same scan file)"});
    v(r.fused_model, {"fused_model", "the model fused from the scan and the CT (caps model fuse)"});
    v(r.output, {"output", "the folder to create", FieldKind::Required, "-o,--output"});
    MeshingFields::fields(r.meshing, v);
    SolverFields::fields(r.solver, v);
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

/// One model's numbers.
struct CompareModelsSide {
  std::string key, label;
  double theta_deg = 0, z_mm = 0, orientation_deg = 0, centre_gap_mm = 0;
  double closing_force_n = 0, max_suture_force_n = 0, max_skin_tension_kpa = 0,
         max_displacement_mm = 0, thickness_mean_mm = 0;
};

struct CompareModelsResult {
  std::string output;
  std::string comparison_json;  ///< model_comparison.json
  std::vector<CompareModelsSide> sides;  ///< ct first
  std::vector<std::string> warnings;

  /// The JSON is model_comparison.json and the output folder.
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v.document(r.comparison_json, {"comparison_json", "model_comparison.json"});
    v(r.output, {"output", "the folder written"});
  }
};

/// Places the plan at the same anatomical point on the scan-built model (through the
/// registration: reference LPS -> scan file -> scan model LPS) and on the fused model (the CT's
/// frame), simulates it on every model and writes ct/, scan/, fused/, the difference pictures,
/// model_comparison.json and report.html into `output`. At least one of scan_model and
/// fused_model is needed; scan_model needs registration.
CompareModelsResult run_compare_models(const CompareModelsRequest& request, Reporter* reporter = nullptr);
std::string to_json(const CompareModelsResult& result);
std::string summary(const CompareModelsResult& result);

// ---- caps model sensitivity ---------------------------------------------------------------

struct SensitivityRequest {
  std::string model, output, credit;
  std::string procedure = study::SensitivityOptions{}.procedure;
  double length = study::SensitivityOptions{}.parameters.at("length");
  double width = study::SensitivityOptions{}.parameters.at("width");
  double orientation = study::SensitivityOptions{}.orientation_deg;
  std::string theta = "-75,75,15";
  std::string z;
  double margin = study::SensitivityOptions{}.margin_mm;
  double thickness = study::SensitivityOptions{}.constant_thickness_mm;
  int threads = study::SensitivityOptions{}.threads;
  MeshingFields meshing;
  SolverFields solver;
  bool force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "the model with a measured thickness (from a volume)", FieldKind::Positional,
                "MODEL"});
    v(r.output, {"output", "the folder to create: sensitivity.png, sensitivity.json, "
                           "sensitivity.csv", FieldKind::Required, "-o,--output"});
    v(r.procedure, {"procedure", "the standard plan: ellipse or z-plasty"});
    v(r.length, {"length", "its length (mm)"});
    v(r.width, {"width", "the ellipse's width (mm)"});
    v(r.orientation, {"orientation", "its direction, deg from superior towards the patient's "
                                     "left (90: horizontal)"});
    v(r.theta, {"theta", "plan centres across: first,last,step (deg; 0 is the face)"});
    v(r.z, {"z", "plan centres up: first,last,step (mm; default: the model's rows less the "
                 "margin, every 10 mm)"});
    v(r.margin, {"margin", "without --z: keep the centres this far from the model's first and "
                           "last rows (mm)"});
    v(r.thickness, {"thickness", "the constant thickness (mm); 0: the median measured over the "
                                 "mapped region"});
    v(r.threads, {"threads", "simulations run at once"});
    MeshingFields::fields(r.meshing, v);
    SolverFields::fields(r.solver, v);
    v(r.credit, {"credit", "a credit line drawn on the picture (e.g. the data's licence)"});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

struct SensitivityResult {
  std::string output;
  int points = 0, planned = 0;
  double constant_thickness_mm = 0;
  /// Over the planned centres: the median and largest |relative change| of the closing force
  /// and of the largest displacement, and the share of centres within 10 % on both.
  double median_force_change = 0, max_force_change = 0;
  double median_displacement_change = 0, max_displacement_change = 0;
  double within_10_percent = 0;
  std::vector<std::string> warnings;
  double seconds = 0;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.output, {"output", "the folder written"});
    v(r.points, {"points", "plan centres on the grid"});
    v(r.planned, {"planned", "centres where the plan could be laid and simulated"});
    v(r.constant_thickness_mm, {"constant_thickness_mm"});
    v.group({"abs_force_change", "|relative change of the closing force|"}, [&] {
      v(r.median_force_change, {"median"});
      v(r.max_force_change, {"max"});
    });
    v.group({"abs_displacement_change", "|relative change of the largest displacement|"}, [&] {
      v(r.median_displacement_change, {"median"});
      v(r.max_displacement_change, {"max"});
    });
    v(r.within_10_percent, {"within_10_percent"});
    v(r.warnings, {"warnings"});
    v.group({"timings_s", "wall-clock seconds (not reproducible)"},
            [&] { v(r.seconds, {"total"}); });
  }
};

/// Runs study::thickness_sensitivity() on the model and writes sensitivity.png (the picture over
/// the face), sensitivity.json and sensitivity.csv into `output`.
SensitivityResult run_sensitivity(const SensitivityRequest& request, Reporter* reporter = nullptr);
std::string to_json(const SensitivityResult& result);
std::string summary(const SensitivityResult& result);

}  // namespace caps::app

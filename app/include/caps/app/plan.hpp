#pragma once
/// @brief Plans as requests and results: `caps plan new`, `check`, `show`, `save-procedure`,
/// `templates`.

#include <map>
#include <string>
#include <vector>

#include "caps/app/fields.hpp"
#include "caps/core/reporter.hpp"

namespace caps::app {

/// A plan as written (or read) and its check.
struct PlanResult {
  std::string output;     ///< the file written (plan or picture), empty for check
  std::string plan_json;  ///< the plan with its check report (edge lengths, warnings) and "ok"
  std::string procedure;
  int points = 0, loop_nodes = 0, suture_pairs = 0;
  double cut_length_mm = 0;
  std::string chart;  ///< the local chart plan new made for the plan (empty: on the model given)
  /// Where its centre is from the nearest landmark the model keeps, in words ("12 mm to the
  /// patient's left and 20 mm up from the glabella"); empty without landmarks.
  std::string near;
  std::vector<std::string> warnings;

  /// The JSON is the plan with its check.
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v.document(r.plan_json, {"plan_json", "the plan with its check"});
  }
};
std::string to_json(const PlanResult& result);
std::string summary(const PlanResult& result);

/// The procedure name of a free incision (PlanNewRequest): the cut drawn through given points.
inline constexpr const char* kFreeIncision = "incision";

struct PlanNewRequest {
  std::string procedure;  ///< a template name, a procedure file (.json) or kFreeIncision
  std::string model, at, at_xyz, output;
  /// A free incision's points along the cut, in order: "THETA,Z;THETA,Z;..." (deg, mm) or, in
  /// points_xyz, "X,Y,Z;X,Y,Z;..." (LPS mm, each taken to the skin point in its direction).
  std::string points, points_xyz;
  double orientation = 0;
  std::map<std::string, double> parameters;  ///< the template's, by name (caps plan templates)
  /// Refuse a plan where the model's cylindrical image cannot hold the skin, instead of placing
  /// it on a local chart made for it beside the plan file (run_plan_new).
  bool no_chart = false;
  bool force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.procedure, {"procedure",
                    "a template (caps plan templates), a procedure file .json, or "
                    "incision (a free cut through --points or --points-xyz)",
                    FieldKind::Positional, "TEMPLATE"});
    v(r.model, {"model", "the patient model directory", FieldKind::Required});
    v(r.at, {"at", "the centre on the skin: THETA,Z (deg, mm), or a landmark and mm to the "
                   "patient's left and up along the skin: glabella+15,20 (docs/landmarks.md)"});
    v(r.at_xyz, {"at_xyz", "the centre as an LPS point X,Y,Z (mm)"});
    v(r.points, {"points", "incision: the cut's points THETA,Z;THETA,Z;... (deg, mm), in order"});
    v(r.points_xyz, {"points_xyz", "incision: the cut's points as LPS X,Y,Z;X,Y,Z;... (mm)"});
    v(r.orientation, {"orientation", "deg from superior towards +theta (the patient's left)"});
    v(r.parameters, {"parameters", "template parameter (see caps plan templates)",
                     FieldKind::Parameters});
    v(r.output, {"output", "the plan file to write", FieldKind::Required, "-o,--output"});
    v(r.no_chart, {"no_chart", "where the model cannot hold the skin (the side of the nose), "
                               "refuse instead of planning on a local chart beside the plan",
                   FieldKind::Flag});
    v(r.force, {"force", "replace an existing output (and its chart)", FieldKind::Flag});
  }
};

/// Lays the procedure on the model, checks it and writes the plan file. A free incision
/// (procedure kFreeIncision) is the "custom" plan of one cutting path through the points given,
/// straight between them in (theta, z) as every plan's segments, with no sutures (the user adds
/// them to the file: docs/plan-format.md); its frame is centred at the points' mean and oriented
/// from the first point towards the last.
///
/// Where the model's cylindrical image cannot hold the skin under a template's plan (undercut or
/// grazing cells: the side of the nose, the alae; plan::SkinNotHeld) and the model is a CT- or
/// MR-built head model, the plan is placed on a local chart facing that skin instead (as caps
/// model chart --at the plan's centre), made beside the plan file (PLAN.chart/ for PLAN.json),
/// at the chart's centre with the same orientation (both from superior towards the patient's
/// left: the chart keeps superior up). The chart is in the head's frame, so the plan is closed
/// in the head's whole face, and simulate, mesh, compare and plan check take the head model for
/// it. The plan's warnings say so; `no_chart` refuses instead.
PlanResult run_plan_new(const PlanNewRequest& request, Reporter* reporter = nullptr);

struct PlanCheckRequest {
  std::string plan, model;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.plan, {"plan", "the plan file", FieldKind::Positional, "PLAN"});
    v(r.model, {"model", "the model directory (default: the one the plan names)"});
  }
};

/// Checks that the plan can be operated on its model (InvalidInput if not).
PlanResult run_plan_check(const PlanCheckRequest& request, Reporter* reporter = nullptr);

struct PlanShowRequest {
  std::string plan, model, output;
  bool thickness = false, force = false;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.plan, {"plan", "the plan file", FieldKind::Positional, "PLAN"});
    v(r.model, {"model", "the model directory (default: the one the plan names)"});
    v(r.thickness, {"thickness", "draw over the thickness map even if the model has colour",
                    FieldKind::Flag});
    v(r.output, {"output", "the PNG to write", FieldKind::Required, "-o,--output"});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

/// Draws the plan over the model (loop numbered, sutures marked) into a PNG.
PlanResult run_plan_show(const PlanShowRequest& request, Reporter* reporter = nullptr);

struct SaveProcedureRequest {
  std::string plan, output;
  bool force = false;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.plan, {"plan", "the plan file", FieldKind::Positional, "PLAN"});
    v(r.output, {"output", "the procedure file to write", FieldKind::Required, "-o,--output"});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

/// Saves a plan's procedure (points, paths, excisions, sutures) to reuse with plan new FILE.json.
PlanResult run_save_procedure(const SaveProcedureRequest& request, Reporter* reporter = nullptr);

// ---- caps plan skin-lines ------------------------------------------------------------------

struct SkinLinesRequest {
  std::string model;
  double spacing_mm = 10;
  double half_length_mm = 4;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "a model directory", FieldKind::Positional, "MODEL_DIR"});
    v(r.spacing_mm, {"spacing_mm", "mm between the lines' seeds, across and up the face [4, 50]",
                     FieldKind::Option, "--spacing"});
    v(r.half_length_mm, {"half_length_mm", "mm each line runs either way from its seed [1, 30]",
                         FieldKind::Option, "--half-length"});
  }
};

/// The relaxed skin tension lines (Borges's map, plan/skin_lines.hpp) traced over a model's face.
struct SkinLinesResult {
  std::string model, map, source;
  int count = 0;
  std::string lines_json;  ///< [{zone, points_lps: [[x, y, z], ...], theta_z: [[t, z], ...]}]
  std::string note;        ///< why there are none
  std::string zones_text;  ///< the zones with their lines, for reading

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model"});
    v(r.map, {"map", "the map's name"});
    v(r.source, {"source", "where the map comes from"});
    v(r.count, {"count", "lines traced"});
    v.json_value(r.lines_json, {"lines"});
    v(r.note, {"note", "why no line is traced, or empty"});
  }
};
/// Traces the map over the model's face (from its landmarks: the nasion, the subnasale and the
/// midline); none, with a note, where the landmarks cannot lay it.
SkinLinesResult run_skin_lines(const SkinLinesRequest& request, Reporter* reporter = nullptr);
std::string to_json(const SkinLinesResult& result);
std::string summary(const SkinLinesResult& result);

struct TemplatesRequest {
  template <class Self, class V>
  static void fields(Self&, V&&) {}
};

struct TemplatesResult {
  std::string json;  ///< [{name, summary, parameters: [{name, unit, default, min, max, meaning}]}]
  std::string text;  ///< the same for reading, parameters spelled as options

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v.document(r.json, {"json", "the templates"});
  }
};
TemplatesResult run_templates(const TemplatesRequest& request, Reporter* reporter = nullptr);
std::string to_json(const TemplatesResult& result);
std::string summary(const TemplatesResult& result);

/// Every template parameter name of the library, sorted (the command line's options).
std::vector<std::string> template_parameter_names();

}  // namespace caps::app

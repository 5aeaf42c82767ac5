#pragma once
/// @brief The verbs of caps, listed once: each is a name (as the command line spells it:
/// "simulate", "model sensitivity"), a request type, a result type, the function that runs it
/// and its help. The command line builds its subcommands from this list, the Python module
/// exposes every verb of it, and the planner's server runs the verbs it serves through it.
///
/// Two views of the one list: for_each_verb() hands every verb with its types (the command
/// line binds the request's fields to options), verbs() the same verbs as JSON in, JSON out
/// (Python, the server).

#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "caps/app/compare_models.hpp"
#include "caps/app/model.hpp"
#include "caps/app/plan.hpp"
#include "caps/app/register.hpp"
#include "caps/app/render.hpp"
#include "caps/app/sheet.hpp"
#include "caps/app/simulation.hpp"
#include "caps/app/slicer.hpp"
#include "caps/app/suggest.hpp"
#include "caps/core/reporter.hpp"

namespace caps::app {

/// What a verb's summary is: a note on what it wrote (the command line prints it on stderr) or
/// the answer itself (on stdout: `caps model info`, `caps plan templates`).
enum class Answer { Written, Printed };

/// One verb with its types.
template <class Request, class Result>
struct Verb {
  using request_type = Request;
  using result_type = Result;
  std::string_view name;  ///< the command line's words: "model from-volume"
  std::string_view help;  ///< the first line says what it does; then an example
  Result (*run)(const Request&, Reporter*);
  Answer answer = Answer::Written;
};
// Deduction guides: an aggregate's template arguments are deduced from its initializer only
// from C++20's P1816 on, which clang 14 (the sanitizer and fuzzer builds) does not implement.
template <class Request, class Result>
Verb(std::string_view, std::string_view, Result (*)(const Request&, Reporter*))
    -> Verb<Request, Result>;
template <class Request, class Result>
Verb(std::string_view, std::string_view, Result (*)(const Request&, Reporter*), Answer)
    -> Verb<Request, Result>;

/// The command line's groups of verbs ("model from-volume" is in "model") and their help.
struct VerbGroup {
  std::string_view name, help;
};
inline constexpr VerbGroup kVerbGroups[] = {
    {"model", "Build and inspect patient models"},
    {"volume", "Inspect CT and MR volumes"},
    {"fem", "Finite-element utilities."},
    {"plan", "Surgical plans: incisions, excisions, sutures"},
};

/// Calls f(Verb<Request, Result>) for every verb, in the command line's order.
template <class F>
void for_each_verb(F&& f) {
  f(Verb{"phantom",
         "Write an analytic head CT phantom (HU, NIfTI) with known tissue thickness.\n"
         "Example: caps phantom -o phantom.nii.gz --voxels 256,256,240 --spacing 1,1,1",
         &run_phantom});
  f(Verb{"model from-volume",
         "Build a patient model from a CT or MR: skin and bone surfaces, cylindrical range "
         "images\nand a measured soft-tissue thickness map.\n"
         "Example: caps model from-volume Cranium.inv3 -o cranium\n"
         "INPUT is a DICOM folder, .nii/.nii.gz, .nrrd/.nhdr, .mha/.mhd or an InVesalius .inv3.",
         &run_from_volume});
  f(Verb{"model chart",
         "Measure a volume-built model's CT again on a local chart: a cylinder whose axis faces "
         "the skin\nat one point, for plans where the head's cylinder meets the skin edge-on "
         "(the side of the nose)\nor behind other skin. The point becomes --at 0,0 of the "
         "chart.\n"
         "Example: caps model chart cranium --at -6,50 -o cranium_nose",
         &run_chart});
  f(Verb{"model from-scan",
         "Build a patient model from a textured surface scan, with a constant soft-tissue "
         "thickness\n(the 1992 CAPS assumption). INPUT is .glb/.gltf, .ply (vertex colours), "
         ".obj (+ .mtl and\ntexture) or .vtk (legacy polydata with texture coordinates), or a "
         "Cyberware-style\ncylindrical range image: a sidecar .json, or a grey PNG with "
         "--r-scale and --z-scale.\n"
         "Example: caps model from-scan head.glb --head-height-mm 230 --thickness 6 -o head\n"
         "Example: caps model from-scan range.png --color color.png --r-scale 0.1 --z-scale 0.7 "
         "--thickness 6 -o head",
         &run_from_scan});
  f(Verb{"model info", "Print a model directory's summary.\nExample: caps model info cranium --json",
         &run_model_info, Answer::Printed});
  f(Verb{"model landmarks",
         "Find a model's anatomical landmarks (glabella, nasion, pronasale, subnasale, "
         "pogonion,\nzygion, exocanthion, tragion; docs/landmarks.md), write them into its "
         "model.json and print them.\nExample: caps model landmarks cranium",
         &run_model_landmarks, Answer::Printed});
  f(Verb{"model features",
         "Find the feature lines on a model's skin (brows, eyelid margins, lip vermilion borders,\n"
         "oral commissures, alar rims; docs/landmarks.md) beside its landmarks, write them into "
         "its\nmodel.json and print them.\nExample: caps model features cranium --picture "
         "cranium/features.png",
         &run_model_features, Answer::Printed});
  f(Verb{"model tissue",
         "Build a model's whole-face tissue model: the soft tissue between skin and bone as\n"
         "tetrahedra (tissue.vtu), the skin's and the bone's level sets (skin.vdb, bone.vdb) and\n"
         "tissue.json, from the CT the model was built from (docs/mesher.md).\n"
         "Example: caps model tissue cranium --force",
         &run_model_tissue});
  f(Verb{"model site",
         "Print the skin point and the soft tissue (thickness, layers) at a place on a model,\n"
         "given as THETA,Z or relative to a landmark.\n"
         "Example: caps model site cranium --at glabella+0,20 --json",
         &run_model_site, Answer::Printed});
  f(Verb{"model export-range",
         "Write a model's skin as a Cyberware-style cylindrical range image: range.png (16-bit "
         "grey),\ncolor.png and the sidecar range.json that from-scan reads.\n"
         "Example: caps model export-range cranium -o cranium_range",
         &run_export_range});
  f(Verb{"model export-slicer",
         "Write a folder that 3D Slicer opens: the CT (or MR) the model was built from (NRRD,\n"
         "patient LPS), a segmentation (tissue.seg.nrrd: dermis, fat, deep tissue, bone), the skin\n"
         "and bone surfaces with the soft-tissue thickness (skin.vtk, bone.vtk), the landmarks and\n"
         "feature lines as markups (.mrk.json); with --plan the plan's cutting paths, with --result\n"
         "the post-operative skin with displacement and tension (docs/slicer.md).\n"
         "Example: caps model export-slicer cranium --plan z.json --result z -o cranium_slicer",
         &run_export_slicer});
  f(Verb{"model pick",
         "Pick the first point of a ray on a model's skin.\n"
         "Example: caps model pick head --ray 0,-400,0,0,1,0",
         &run_pick, Answer::Printed});
  f(Verb{"model register",
         "Register a surface scan (partial coverage allowed) to a model's skin: a rigid motion\n"
         "(and optionally a uniform scale) found without landmarks, the scan-to-model matrix,\n"
         "residual statistics and a distance map (distance.ply, distance.png). Refuses a scan\n"
         "whose residual says it is of another head.\n"
         "Example: caps model register face.ply --to cranium -o face_reg",
         &run_register});
  f(Verb{"model fuse",
         "Build a model whose skin colour (and with --scan-skin, skin) comes from a registered\n"
         "scan and whose bone, thickness and layers come from a CT model.\n"
         "Example: caps model fuse face.ply --to cranium --registration face_reg/registration.json "
         "-o cranium_fused",
         &run_fuse});
  f(Verb{"model sensitivity",
         "Map where a constant soft-tissue thickness misleads: a small standard plan (a 20 x 7 mm\n"
         "ellipse) at a grid of points over the face, simulated with the measured and with one\n"
         "constant thickness; sensitivity.png shows the change in closing force and displacement.\n"
         "Example: caps model sensitivity cranium -o cranium_sensitivity",
         &run_sensitivity});
  f(Verb{"model color-picture",
         "Draw a model's skin colour with axes and its credit line.\n"
         "Example: caps model color-picture head -o head_color.png",
         &run_color_picture});
  f(Verb{"volume info",
         "Print a volume's geometry (LPS), modality, value range and how it was read.\n"
         "Example: caps volume info ct_folder/ --json",
         &run_volume_info, Answer::Printed});
  f(Verb{"solve",
         "Solve a caps-mesh directory (fixed nodes, sutures; small-strain linear elasticity, or "
         "finite strain with --material neo-hookean); writes result.vtu and result.json.\n"
         "Example: caps solve mesh -o result --solver mumps",
         &run_solve});
  f(Verb{"fem box",
         "Write a box mesh directory of Hex20 (or Wedge15) elements, bottom fixed, optionally "
         "with a sutured slot.\nExample: caps fem box -o m --cells 5,6,2 --slot",
         &run_box});
  f(Verb{"plan new",
         "Lay a procedure from the library (or a procedure file) on the model and check it.\n"
         "Example: caps plan new z-plasty --model cranium --at 0,95 --length 20 -o z.json",
         &run_plan_new});
  f(Verb{"plan check",
         "Check that a plan can be operated (exit 2 if not).\nExample: caps plan check z.json",
         &run_plan_check});
  f(Verb{"plan show",
         "Draw the plan over the model: loop numbered, sutures marked.\n"
         "Example: caps plan show z.json -o z.png",
         &run_plan_show});
  f(Verb{"plan sheet",
         "Write a plan's operating-room sheet: one page (PDF; --png also a PNG) with the incision "
         "drawn 1:1\non the skin around it laid flat, its key points measured from palpable "
         "landmarks, and with\n--result the closure's predicted forces and feature distortions.\n"
         "Example: caps plan sheet z.json --result z -o z-sheet.pdf --png",
         &run_plan_sheet});
  f(Verb{"plan save-procedure",
         "Save a plan's procedure (points, paths, excisions, sutures) to reuse elsewhere with "
         "caps plan new FILE.json",
         &run_save_procedure});
  f(Verb{"plan suggest",
         "For a lesion: the library's closures that fit it laid around it at every orientation, "
         "checked,\nclosed in the whole face and ranked (suggestions.json, suggestions.png, each "
         "design's plan).\n"
         "Example: caps plan suggest --model cranium --at 30,105 --diameter 10 -o suggest",
         &run_plan_suggest});
  f(Verb{"plan skin-lines",
         "Trace the relaxed skin tension lines (Borges 1984's map, laid by the model's nasion,\n"
         "subnasale and midline; docs/plan.md) over a model's face and print them.\n"
         "Example: caps plan skin-lines cranium --json",
         &run_skin_lines, Answer::Printed});
  f(Verb{"plan templates", "List the procedure library and its parameters.", &run_templates,
         Answer::Printed});
  f(Verb{"mesh",
         "Mesh a wound border on a patient model (paper section 6): mesh.vtu + mesh.json (for "
         "caps solve), mesh.inp (CalculiX), surface.png, section.png, summary.json.\n"
         "Example: caps mesh --model cranium --plan zplasty.json -o mesh",
         &run_mesh});
  f(Verb{"simulate",
         "Mesh a plan on a patient model and solve the wound closure in one go: the mesh and "
         "result files of caps mesh and caps solve in one folder.\n"
         "Example: caps simulate --model cranium --plan zplasty.json -o result",
         &run_simulate});
  f(Verb{"render",
         "Pre- and post-operative images of a simulation: pre_<view>.png and post_<view>.png, "
         "same camera, displacement-mapped skin (paper section 4); optionally "
         "displacement_<view>.png (|displacement|, mm), tension_<view>.png (skin tension: max "
         "principal stress, kPa), skin.glb (glTF morph target) and transition_<view>.gif.\n"
         "Example: caps render esim --model cranium -o esim-images",
         &run_render});
  f(Verb{"compare",
         "Simulate one plan with the measured soft-tissue thickness and with a constant one\n"
         "(the 1992 assumption for surface scans), on the same skin and surface mesh, and\n"
         "write report.html with a table of the differences and both results' pictures.\n"
         "Example: caps compare --model cranium --plan ellipse.json -o compare",
         &run_compare});
  f(Verb{"compare-models",
         "Simulate one plan on the patient's CT model and on the models made from a surface\n"
         "scan of the same patient: the scan alone (constant thickness, the 1992 way) and the\n"
         "scan fused with the CT. The plan is placed at the same anatomical point on each (the\n"
         "registration carries it); report.html shows the numbers side by side and the\n"
         "differences in displacement (mm) and skin tension (kPa) on the CT's skin.\n"
         "Example: caps compare-models --model cranium --plan ellipse.json --scan-model face "
         "--registration face_reg/registration.json --fused-model cranium_fused -o models",
         &run_compare_models});
}

/// One verb as JSON in, JSON out.
struct VerbEntry {
  std::string name;  ///< the command line's words: "model from-volume"
  std::string key;   ///< the same joined by "_": "model_from_volume" (Python's name)
  std::string help;
  Answer answer = Answer::Written;
  /// Reads the request (read_request: errors name `source`), runs the verb, answers to_json().
  std::function<std::string(const std::string& request_json, const std::string& source,
                            Reporter* reporter)>
      run_json;
  /// Reads the request only (the errors run_json would give for it, before any work).
  std::function<void(const std::string& request_json, const std::string& source)> check_json;
  /// Every field of the request with its default, as JSON (write_request).
  std::function<std::string()> defaults_json;
};

/// Every verb, in the command line's order.
const std::vector<VerbEntry>& verbs();

/// "model from-volume", "model-from-volume" -> "model_from_volume".
std::string verb_key(std::string_view name);

/// The verb called `name` (either spelling); InvalidInput listing the verbs when there is none.
const VerbEntry& find_verb(std::string_view name);

}  // namespace caps::app

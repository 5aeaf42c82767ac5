#pragma once
/// @brief `caps model export-slicer`: a folder that 3D Slicer opens as its users expect
/// (docs/slicer.md). Everything in it is in patient LPS millimetres, caps's own frame (the
/// frame of every reader's Volume, volume/volume.hpp), and says so in each file:
///   ct.nrrd (mr.nrrd, volume.nrrd)  the volume the model was built from, NRRD with `space:
///                                   left-posterior-superior`, `space directions`, `space origin`;
///   tissue.seg.nrrd                 Slicer's segmentation (one labelmap layer on the volume's
///                                   grid): dermis, subcutaneous fat, deep tissue, bone;
///   skin.vtk, bone.vtk              the model's surfaces (legacy VTK polydata, header
///                                   "SPACE=LPS") with the soft-tissue thickness as point data;
///   landmarks.mrk.json              the landmarks (Slicer markups, a point list, LPS, mm);
///   features/<line>.mrk.json        the feature lines found on the skin (open curves);
///   plan/incision_<n>.mrk.json      with --plan: the plan's cutting paths on the skin (curves);
///   skin_postop.vtk                 with --result: the post-operative skin with displacement
///                                   (mm) and skin tension (kPa) as point data;
///   summary.json                    what was written, the frame, the segments, the warnings.

#include <string>
#include <vector>

#include "caps/app/fields.hpp"
#include "caps/core/reporter.hpp"

namespace caps::app {

struct ExportSlicerRequest {
  std::string model, output, plan, result;
  bool force = false;
  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "a model directory", FieldKind::Positional, "MODEL_DIR"});
    v(r.output, {"output", "the folder to create", FieldKind::Required, "-o,--output"});
    v(r.plan, {"plan", "a plan on this model: its cutting paths as markups curves"});
    v(r.result, {"result",
                 "a simulation folder (caps simulate) of a plan on this model: the "
                 "post-operative skin with displacement and tension"});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

struct ExportSlicerResult {
  std::string output;
  std::vector<std::string> files;  ///< relative to `output`, in the order written
  std::string volume_file;         ///< "" when the source volume could not be written
  std::string segments_text;       ///< "dermis 1234, fat 567, ..." (summary)
  int landmarks = 0, curves = 0;   ///< landmark points and curves (features, plan) written
  double max_displacement_mm = 0, max_tension_kpa = 0;  ///< with --result
  std::vector<std::string> warnings;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.output, {"output", "the folder written"});
    v(r.files, {"files", "relative to output"});
    v(r.volume_file, {"volume_file"});
    v(r.segments_text, {"segments"});
    v(r.landmarks, {"landmarks"});
    v(r.curves, {"curves"});
    v(r.max_displacement_mm, {"max_displacement_mm"});
    v(r.max_tension_kpa, {"max_tension_kpa"});
    v(r.warnings, {"warnings"});
  }
};

/// Writes the folder (atomically: nothing is left on a refusal or an error). Throws InvalidInput
/// for a plan or result of another model, or an output over an input; the volume the model was
/// built from missing or changed is a warning (the rest is written).
ExportSlicerResult run_export_slicer(const ExportSlicerRequest& request,
                                     Reporter* reporter = nullptr);
std::string to_json(const ExportSlicerResult& result);
std::string summary(const ExportSlicerResult& result);

}  // namespace caps::app

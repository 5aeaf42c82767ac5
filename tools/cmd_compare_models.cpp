// caps compare-models: bound to app/ (caps/app/compare_models.hpp).
//   caps model register face.ply --to /tmp/cranium -o /tmp/face_reg
//   caps model from-scan face.ply --thickness 6 -o /tmp/face_model
//   caps model fuse face.ply --to /tmp/cranium --registration /tmp/face_reg/registration.json -o /tmp/cranium_fused
//   caps compare-models --model /tmp/cranium --plan /tmp/e.json --scan-model /tmp/face_model --registration /tmp/face_reg/registration.json --fused-model /tmp/cranium_fused -o /tmp/e-models
#include "caps/app/compare_models.hpp"
#include "commands.hpp"

namespace caps::cli {

void add_compare_models(CLI::App& app, Common& common, Action& action) {
  add_verb(&app, "compare-models",
           "Simulate one plan on the patient's CT model and on the models made from a surface\n"
           "scan of the same patient: the scan alone (constant thickness, the 1992 way) and the\n"
           "scan fused with the CT. The plan is placed at the same anatomical point on each (the\n"
           "registration carries it); report.html shows the numbers side by side and the\n"
           "differences in displacement (mm) and skin tension (kPa) on the CT's skin.\n"
           "Example: caps compare-models --model cranium --plan ellipse.json --scan-model face "
           "--registration face_reg/registration.json --fused-model cranium_fused -o models",
           &app::run_compare_models, common, action);
}

}  // namespace caps::cli

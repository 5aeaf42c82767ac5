// caps model, caps volume info and caps phantom: bound to app/ (caps/app/model.hpp).
//   caps phantom -o /tmp/phantom.nii.gz --voxels 256,256,240 --spacing 1,1,1
//   caps volume info ../shared/data/ct/ge-head-tilt --json
//   caps model from-volume /usr/share/doc/invesalius-examples/examples/Cranium.inv3 -o /tmp/cranium
//   caps model from-scan ../shared/data/scan/leeperrysmith/LeePerrySmith.glb --texture ../shared/data/scan/leeperrysmith/Map-COL.jpg --flip-v --head-height-mm 230 --thickness 6 -o /tmp/lps
//   caps model chart /tmp/cranium --at -6,50 -o /tmp/cranium_nose
//   caps model info /tmp/cranium --json
//   caps model pick /tmp/lps --ray 0,-400,0,0,1,0 --json
//   caps model export-range /tmp/lps -o /tmp/lps_range
//   caps model color-picture /tmp/lps -o /tmp/lps_color.png --force
//   caps model register ../shared/data/scan/leeperrysmith/LeePerrySmith.glb --to /tmp/cranium --scan-scale 29 --up +y --front +z --accept-other-head --credit "Infinite, 3D Head Scan by Lee Perry-Smith, CC BY 3.0 (www.triplegangers.com)" -o /tmp/lps_reg
//   caps model fuse ../shared/data/scan/leeperrysmith/LeePerrySmith.glb --to /tmp/cranium --registration /tmp/lps_reg/registration.json --texture ../shared/data/scan/leeperrysmith/Map-COL.jpg --flip-v -o /tmp/cranium_fused
//   caps model sensitivity /tmp/cranium --theta -60,60,30 --z 60,120,30 -o /tmp/cranium_sensitivity
#include "caps/app/compare_models.hpp"
#include "caps/app/model.hpp"
#include "caps/app/register.hpp"
#include "commands.hpp"

namespace caps::cli {

void add_phantom(CLI::App& app, Common& common, Action& action) {
  add_verb(&app, "phantom",
           "Write an analytic head CT phantom (HU, NIfTI) with known tissue thickness.\n"
           "Example: caps phantom -o phantom.nii.gz --voxels 256,256,240 --spacing 1,1,1",
           &app::run_phantom, common, action);
}

void add_volume(CLI::App& app, Common& common, Action& action) {
  auto* volume = app.add_subcommand("volume", "Inspect CT and MR volumes");
  volume->require_subcommand(1);
  add_verb(volume, "info",
           "Print a volume's geometry (LPS), modality, value range and how it was read.\n"
           "Example: caps volume info ct_folder/ --json",
           &app::run_volume_info, common, action, Print::Stdout);
}

void add_model(CLI::App& app, Common& common, Action& action) {
  auto* model = app.add_subcommand("model", "Build and inspect patient models");
  model->require_subcommand(1);
  add_verb(model, "from-volume",
           "Build a patient model from a CT or MR: skin and bone surfaces, cylindrical range "
           "images\nand a measured soft-tissue thickness map.\n"
           "Example: caps model from-volume Cranium.inv3 -o cranium\n"
           "INPUT is a DICOM folder, .nii/.nii.gz, .nrrd/.nhdr, .mha/.mhd or an InVesalius .inv3.",
           &app::run_from_volume, common, action);
  add_verb(model, "chart",
           "Measure a volume-built model's CT again on a local chart: a cylinder whose axis faces "
           "the skin\nat one point, for plans where the head's cylinder meets the skin edge-on "
           "(the side of the nose)\nor behind other skin. The point becomes --at 0,0 of the "
           "chart.\n"
           "Example: caps model chart cranium --at -6,50 -o cranium_nose",
           &app::run_chart, common, action);
  add_verb(model, "from-scan",
           "Build a patient model from a textured surface scan, with a constant soft-tissue "
           "thickness\n(the 1992 CAPS assumption). INPUT is .glb/.gltf, .ply (vertex colours), "
           ".obj (+ .mtl and\ntexture) or .vtk (legacy polydata with texture coordinates), or a "
           "Cyberware-style\ncylindrical range image: a sidecar .json, or a grey PNG with "
           "--r-scale and --z-scale.\n"
           "Example: caps model from-scan head.glb --head-height-mm 230 --thickness 6 -o head\n"
           "Example: caps model from-scan range.png --color color.png --r-scale 0.1 --z-scale 0.7 "
           "--thickness 6 -o head",
           &app::run_from_scan, common, action);
  add_verb(model, "info", "Print a model directory's summary.\nExample: caps model info cranium --json",
           &app::run_model_info, common, action, Print::Stdout);
  add_verb(model, "landmarks",
           "Find a model's anatomical landmarks (glabella, nasion, pronasale, subnasale, "
           "pogonion,\nzygion, exocanthion, tragion; docs/landmarks.md), write them into its "
           "model.json and print them.\nExample: caps model landmarks cranium",
           &app::run_model_landmarks, common, action, Print::Stdout);
  add_verb(model, "site",
           "Print the skin point and the soft tissue (thickness, layers) at a place on a model,\n"
           "given as THETA,Z or relative to a landmark.\n"
           "Example: caps model site cranium --at glabella+0,20 --json",
           &app::run_model_site, common, action, Print::Stdout);
  add_verb(model, "export-range",
           "Write a model's skin as a Cyberware-style cylindrical range image: range.png (16-bit "
           "grey),\ncolor.png and the sidecar range.json that from-scan reads.\n"
           "Example: caps model export-range cranium -o cranium_range",
           &app::run_export_range, common, action);
  add_verb(model, "pick",
           "Pick the first point of a ray on a model's skin.\n"
           "Example: caps model pick head --ray 0,-400,0,0,1,0",
           &app::run_pick, common, action, Print::Stdout);
  add_verb(model, "register",
           "Register a surface scan (partial coverage allowed) to a model's skin: a rigid motion\n"
           "(and optionally a uniform scale) found without landmarks, the scan-to-model matrix,\n"
           "residual statistics and a distance map (distance.ply, distance.png). Refuses a scan\n"
           "whose residual says it is of another head.\n"
           "Example: caps model register face.ply --to cranium -o face_reg",
           &app::run_register, common, action);
  add_verb(model, "fuse",
           "Build a model whose skin colour (and with --scan-skin, skin) comes from a registered\n"
           "scan and whose bone, thickness and layers come from a CT model.\n"
           "Example: caps model fuse face.ply --to cranium --registration face_reg/registration.json "
           "-o cranium_fused",
           &app::run_fuse, common, action);
  add_verb(model, "sensitivity",
           "Map where a constant soft-tissue thickness misleads: a small standard plan (a 20 x 7 mm\n"
           "ellipse) at a grid of points over the face, simulated with the measured and with one\n"
           "constant thickness; sensitivity.png shows the change in closing force and displacement.\n"
           "Example: caps model sensitivity cranium -o cranium_sensitivity",
           &app::run_sensitivity, common, action);
  add_verb(model, "color-picture",
           "Draw a model's skin colour with axes and its credit line.\n"
           "Example: caps model color-picture head -o head_color.png",
           &app::run_color_picture, common, action);
}

}  // namespace caps::cli

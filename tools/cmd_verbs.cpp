// The subcommands of caps' verbs, built from app's list of verbs (caps/app/verbs.hpp): each binds
// its options to the verb's request, runs it and prints its result.
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
//   caps plan templates
//   caps plan new z-plasty --model /tmp/cranium --at 0,95 --length 20 --angle 60 --orientation 90 -o /tmp/z.json
//   caps plan new ellipse --model /tmp/cranium --at 0,95 --length 30 --width 9 -o /tmp/e.json --force
//   caps plan check /tmp/z.json --json
//   caps plan show /tmp/z.json -o /tmp/z.png
//   caps plan save-procedure /tmp/z.json -o /tmp/my_z.json
//   caps plan new /tmp/my_z.json --model /tmp/cranium --at 20,90 -o /tmp/z2.json
//   caps plan new incision --model /tmp/cranium --points '20,100;28,108;36,100' -o /tmp/cut.json
//   caps mesh --model /tmp/cranium --plan /tmp/z.json -o /tmp/zplasty-mesh
//   caps mesh --model /tmp/cranium --border border.json -o /tmp/m --layers 3 --mesh-size 1.5 --extent 60 --rim free --force --json
//   caps solve /tmp/zplasty-mesh -o /tmp/zplasty-result --solver cholmod --E 50 --nu 0.45
//   caps simulate --model /tmp/cranium --plan /tmp/z.json -o /tmp/zplasty-result --render
//   caps compare --model /tmp/cranium --plan /tmp/e.json -o /tmp/e-compare --thickness 6
//   caps fem box -o /tmp/slot-mesh --box-size 30,20,6 --cells 5,6,2 --slot
//   caps render /tmp/esim --model /tmp/cranium -o /tmp/esim-images
//   caps render /tmp/esim --model /tmp/cranium -o /tmp/esim-overlays --plan /tmp/e.json --displacement-map --views plan --force
//   caps render /tmp/esim --model /tmp/cranium -o /tmp/esim-tension --tension-map --tension-max-kpa 20 --views plan --force --json
//   caps render /tmp/esim --model /tmp/cranium -o /tmp/esim-anim --views plan --image-size 400 --gltf --animation --force
//   caps model register face.ply --to /tmp/cranium -o /tmp/face_reg
//   caps model from-scan face.ply --thickness 6 -o /tmp/face_model
//   caps model fuse face.ply --to /tmp/cranium --registration /tmp/face_reg/registration.json -o /tmp/cranium_fused
//   caps compare-models --model /tmp/cranium --plan /tmp/e.json --scan-model /tmp/face_model --registration /tmp/face_reg/registration.json --fused-model /tmp/cranium_fused -o /tmp/e-models
#include <map>

#include "caps/app/verbs.hpp"
#include "commands.hpp"

namespace caps::cli {

void add_verbs(CLI::App& app, Common& common, Action& action) {
  std::map<std::string, CLI::App*> groups;
  const auto group = [&](const std::string& name) {
    CLI::App*& g = groups[name];
    if (!g) {
      std::string help;
      for (const app::VerbGroup& known : app::kVerbGroups)
        if (known.name == name) help = known.help;
      g = app.add_subcommand(name, help);
      g->require_subcommand(1);
    }
    return g;
  };
  app::for_each_verb([&](const auto& verb) {
    const std::string name(verb.name);
    const auto space = name.find(' ');
    CLI::App* parent = space == std::string::npos ? &app : group(name.substr(0, space));
    add_verb(parent, space == std::string::npos ? name : name.substr(space + 1),
             std::string(verb.help), verb.run, common, action,
             verb.answer == app::Answer::Printed ? Print::Stdout : Print::Stderr);
  });
}

}  // namespace caps::cli

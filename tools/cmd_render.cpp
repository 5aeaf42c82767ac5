// caps render: bound to app/ (caps/app/render.hpp).
//   caps simulate --model /tmp/cranium --plan /tmp/e.json -o /tmp/esim
//   caps render /tmp/esim --model /tmp/cranium -o /tmp/esim-images
//   caps render /tmp/esim --model /tmp/cranium -o /tmp/esim-overlays --plan /tmp/e.json --displacement-map --views plan --force
//   caps render /tmp/esim --model /tmp/cranium -o /tmp/esim-tension --tension-map --tension-max-kpa 20 --views plan --force --json
//   caps render /tmp/esim --model /tmp/cranium -o /tmp/esim-anim --views plan --image-size 400 --gltf --animation --force
#include "caps/app/render.hpp"
#include "commands.hpp"

namespace caps::cli {

void add_render(CLI::App& app, Common& common, Action& action) {
  add_verb(&app, "render",
           "Pre- and post-operative images of a simulation: pre_<view>.png and post_<view>.png, "
           "same camera, displacement-mapped skin (paper section 4); optionally "
           "displacement_<view>.png (|displacement|, mm), tension_<view>.png (skin tension: max "
           "principal stress, kPa), skin.glb (glTF morph target) and transition_<view>.gif.\n"
           "Example: caps render esim --model cranium -o esim-images",
           &app::run_render, common, action);
}

}  // namespace caps::cli

#pragma once
/// @brief `caps render` as a request and a result: pre- and post-operative pictures of a
/// simulation, overlays, glTF and animations.

#include <string>
#include <vector>

#include "caps/app/fields.hpp"
#include "caps/core/reporter.hpp"
#include "caps/render/animation.hpp"

namespace caps::app {

struct RenderRequest {
  std::string result, model, output, views, plan;
  int image_size = 800, subdivisions = 0, frames = render::kGifDefaultFrames;
  bool gltf = false, animation = false, displacement_map = false, tension_map = false;
  double tension_max_kpa = 0;  ///< top of the tension scale; 0 = the 99th percentile
  bool force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.result, {"result", "a caps simulate (or caps solve) output directory",
                 FieldKind::Positional, "RESULT_DIR"});
    v(r.model, {"model", "patient model directory", FieldKind::Required});
    v(r.output, {"output", "image directory to create", FieldKind::Required, "-o,--output"});
    v(r.views, {"views", "comma-separated: front, oblique, side, plan (default: all four; for "
                         "--animation: plan)"});
    v(r.image_size, {"image_size", "image width and height (pixels)", FieldKind::Option, {},
                     "--size"});
    v(r.subdivisions, {"subdivisions", "micropolygons along each element edge (1..64); 0 = the "
                                       "model's full resolution"});
    v(r.plan, {"plan", "draw this plan's cutting lines over the pre-operative images"});
    v(r.displacement_map, {"displacement_map", "also write displacement_<view>.png: the skin "
                                               "coloured by displacement, with a colour bar in mm",
                           FieldKind::Flag});
    v(r.tension_map, {"tension_map", "also write tension_<view>.png: the post-operative skin "
                                     "coloured by the skin tension (maximum principal stress at "
                                     "the skin surface) with a colour bar in kPa",
                      FieldKind::Flag});
    v(r.tension_max_kpa, {"tension_max_kpa", "top of the --tension-map scale (kPa); 0 = the 99th "
                                             "percentile over the skin (the peaks at sutured "
                                             "corners are singular and grow with refinement)"});
    v(r.gltf, {"gltf", "also write skin.glb: glTF 2.0, pre-operative skin with the "
                       "post-operative skin as a morph target and a 2 s animation",
               FieldKind::Flag});
    v(r.animation, {"animation", "also write transition_<view>.gif, the looping pre-to-post "
                                 "transition", FieldKind::Flag});
    v(r.frames, {"frames", "frames of each --animation (2..600)"});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

struct RenderResult {
  std::string output;
  int skin_elements = 0, subdivisions = 0, micropolygon_vertices = 0, triangles = 0;
  double max_displacement_mm = 0, wound_area_pre_mm2 = 0, wound_area_post_mm2 = 0;
  std::vector<std::string> images, animations;
  bool gltf = false;
  int frames = 0;
  bool has_tension = false;
  double max_skin_tension_kpa = 0, min_skin_tension_kpa = 0, tension_scale_max_kpa = 0;
  std::vector<std::string> warnings;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.output, {"output", "the image directory written"});
    v(r.skin_elements, {"skin_elements"});
    v(r.subdivisions, {"subdivisions"});
    v(r.micropolygon_vertices, {"micropolygon_vertices"});
    v(r.triangles, {"triangles"});
    v(r.max_displacement_mm, {"max_displacement_mm"});
    v.group({"wound_area_mm2"}, [&] {
      v(r.wound_area_pre_mm2, {"pre"});
      v(r.wound_area_post_mm2, {"post"});
    });
    v(r.images, {"images"});
    v(r.warnings, {"warnings"});
    v.when(r.has_tension, [&] {
      v(r.max_skin_tension_kpa, {"max_skin_tension_kpa"});
      v(r.min_skin_tension_kpa, {"min_skin_tension_kpa"});
      v(r.tension_scale_max_kpa, {"tension_scale_max_kpa"});
    });
    v.when(r.gltf, [&] { v.computed({"gltf"}, [] { return std::string("skin.glb"); }); });
    v.when(!r.animations.empty() || r.frames, [&] {
      v(r.animations, {"animations"});
      v(r.frames, {"frames"});
    });
  }
};

/// Renders a simulation's result directory on its model into `output`.
RenderResult run_render(const RenderRequest& request, Reporter* reporter = nullptr);
std::string to_json(const RenderResult& result);
std::string summary(const RenderResult& result);

}  // namespace caps::app

// caps render: pre- and post-operative pictures of a simulation (paper section 4): the skin
// faces of the elements are displacement-mapped with micropolygons carrying the model's full
// resolution range and colour data, the rest of the head is the range mesh, and each standard
// view is ray-cast with the same camera before and after the closure.
//   caps model from-volume /usr/share/doc/invesalius-examples/examples/Cranium.inv3 -o /tmp/cranium
//   caps plan new ellipse --model /tmp/cranium --at 25,105 -o /tmp/e.json
//   caps simulate --model /tmp/cranium --plan /tmp/e.json -o /tmp/esim
//   caps render /tmp/esim --model /tmp/cranium -o /tmp/esim-images
//   caps render /tmp/esim --model /tmp/cranium -o /tmp/esim-overlays --plan /tmp/e.json --displacement-map --views plan --force
//   caps render /tmp/esim --model /tmp/cranium -o /tmp/esim-tension --tension-map --views plan,oblique --force
//   caps render /tmp/esim --model /tmp/cranium -o /tmp/esim-tension --tension-map --tension-max-kpa 20 --views plan --force --json
//   caps render /tmp/esim --model /tmp/cranium -o /tmp/esim-plan --views plan --size 400 --force --json
//   caps render /tmp/esim --model /tmp/cranium -o /tmp/esim-anim --views plan --size 400 --gltf --animation --force
#include <cmath>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/fem/result_io.hpp"
#include "caps/render/animation.hpp"
#include "caps/render/gltf_export.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/render/overlay.hpp"
#include "caps/render/render.hpp"
#include "caps/render/simulation_report.hpp"
#include "caps/render/skin_surface.hpp"
#include "caps/surface/patient_model.hpp"
#include "commands.hpp"

namespace caps::cli {
namespace {

struct RenderArgs {
  std::string result, model, output, views = "front,oblique,side,plan";
  int size = 800, subdivisions = 0, frames = render::kGifDefaultFrames;
  bool gltf = false, animation = false, views_given = false, displacement_map = false,
       tension_map = false;
  double tension_max_kpa = 0;  // top of the tension scale; 0 = the 99th percentile
  std::string plan;  // draw its cutting lines over the pre-operative images
};

void run_render(const RenderArgs& a, const Common& common) {
  std::vector<render::View> views;
  std::stringstream list(a.views);
  for (std::string v; std::getline(list, v, ',');) views.push_back(render::parse_view(v));
  if (views.empty()) throw InvalidInput("--views: name at least one of front,oblique,side,plan");
  if (a.size < 16 || a.size > 8192)
    throw InvalidInput(cat("--size ", a.size, ": expected 16..8192 pixels"));
  if (a.frames < 2 || a.frames > 600)
    throw InvalidInput(cat("--frames ", a.frames, ": expected 2..600"));
  if (!(a.tension_max_kpa >= 0) || !std::isfinite(a.tension_max_kpa))
    throw InvalidInput(cat("--tension-max-kpa ", a.tension_max_kpa,
                           ": expected a positive stress in kPa (0 = the 99th percentile)"));
  const fem::Mesh mesh = fem::read_mesh_dir(a.result);
  const Eigen::MatrixX3d u = fem::read_result_displacement(a.result, mesh.n_nodes());
  const PatientModel model = PatientModel::load(a.model);
  const int n = a.subdivisions > 0 ? a.subdivisions
                                   : render::full_resolution_subdivisions(model, mesh);
  const render::SkinSurfaces skin = render::displaced_skin(model, mesh, &u, n);
  const auto [fill_pre_mm2, fill_post_mm2] = render::wound_fill_area_mm2(skin);
  OutputDirectory out(a.output, common.force);
  render::RenderOptions o;
  o.width = o.height = a.size;
  render::Overlays overlays;
  if (a.displacement_map) overlays.scalar_maps.push_back(render::displacement_map(skin));
  if (a.tension_map)
    overlays.scalar_maps.push_back(render::tension_map(
        skin, mesh, fem::read_result_max_principal(a.result, mesh.n_nodes()), a.tension_max_kpa));
  if (!a.plan.empty()) overlays.plan_lines = render::plan_lines(plan::read_plan(a.plan), model);
  const auto files = render::render_views_with_overlays(model, skin, views, o, overlays, out.path());
  if (a.gltf) render::write_gltf(skin, out.path() / "skin.glb");
  std::vector<std::filesystem::path> gifs;
  if (a.animation) {  // of the plan view unless views were named
    const std::vector<render::View> anim_views =
        a.views_given ? views : std::vector{render::View::Plan};
    gifs = render::write_transition_gifs(model, skin, anim_views, o, a.frames, out.path());
  }
  out.commit();
  nlohmann::json j{{"output", a.output},
                   {"skin_elements", skin.skin_elements.size()},
                   {"subdivisions", n},
                   {"micropolygon_vertices", skin.n_micropolygon_vertices},
                   {"triangles", skin.pre.F.rows()},
                   {"max_displacement_mm", u.rowwise().norm().maxCoeff()},
                   {"wound_area_mm2", {{"pre", fill_pre_mm2}, {"post", fill_post_mm2}}},
                   {"images", nlohmann::json::array()}};
  for (const auto& f : files) j["images"].push_back(f.filename().string());
  for (const auto& m : overlays.scalar_maps)
    if (m.name == "tension") {  // over the micropolygons (the range mesh is 0 by definition)
      j["max_skin_tension_kpa"] = m.value.head(skin.n_micropolygon_vertices).maxCoeff();
      j["min_skin_tension_kpa"] = m.value.head(skin.n_micropolygon_vertices).minCoeff();
      j["tension_scale_max_kpa"] = m.max_value;
    }
  if (a.gltf) j["gltf"] = "skin.glb";
  if (a.animation) {
    j["animations"] = nlohmann::json::array();
    for (const auto& f : gifs) j["animations"].push_back(f.filename().string());
    j["frames"] = a.frames;
  }
  if (common.json) std::cout << j.dump(2) << "\n";
  else if (!common.quiet)
    std::cerr << "caps render: " << files.size() << " images" << (a.gltf ? ", skin.glb" : "")
              << (a.animation ? cat(", ", gifs.size(), " animations") : std::string()) << " in "
              << a.output << " (" << skin.skin_elements.size() << " skin faces, "
              << skin.n_micropolygon_vertices << " micropolygon vertices)\n";
}

}  // namespace

void add_render(CLI::App& app, Common& common, Action& action) {
  auto a = std::make_shared<RenderArgs>();
  auto* cmd = app.add_subcommand(
      "render", "Pre- and post-operative images of a simulation: pre_<view>.png and "
                "post_<view>.png, same camera, displacement-mapped skin (paper section 4); "
                "optionally displacement_<view>.png (|displacement|, mm), tension_<view>.png "
                "(skin tension: max principal stress, kPa), skin.glb (glTF morph target) and "
                "transition_<view>.gif.\n"
                "Example: caps render esim --model cranium -o esim-images");
  cmd->add_option("result", a->result, "a caps simulate (or caps solve) output directory")
      ->required();
  cmd->add_option("--model", a->model, "patient model directory")->required();
  cmd->add_option("-o,--output", a->output, "image directory to create")->required();
  auto* views = cmd->add_option("--views", a->views, "comma-separated: front, oblique, side, plan")
                    ->capture_default_str();
  cmd->add_option("--size", a->size, "image width and height (pixels)")->capture_default_str();
  cmd->add_option("--subdivisions", a->subdivisions,
                  "micropolygons along each element edge (1..64); 0 = the model's full resolution")->capture_default_str();
  cmd->add_option("--plan", a->plan, "draw this plan's cutting lines over the pre-operative images");
  cmd->add_flag("--displacement-map", a->displacement_map,
                "also write displacement_<view>.png: the skin coloured by displacement, with a "
                "colour bar in mm");
  auto* tension = cmd->add_flag("--tension-map", a->tension_map,
                "also write tension_<view>.png: the post-operative skin coloured by the skin "
                "tension (maximum principal stress at the skin surface, result.vtu's "
                "max_principal) with a colour bar in kPa; compression (<= 0) is the bottom colour");
  cmd->add_option("--tension-max-kpa", a->tension_max_kpa,
                  "top of the --tension-map scale (kPa); 0 = the 99th percentile over the "
                  "skin (the peaks at sutured corners are singular and grow with refinement)")
      ->capture_default_str()
      ->needs(tension);
  cmd->add_flag("--gltf", a->gltf,
                "also write skin.glb: glTF 2.0, pre-operative skin with the post-operative skin as "
                "a morph target and a 2 s animation (metres, +Y up, face along +Z)");
  cmd->add_flag("--animation", a->animation,
                "also write transition_<view>.gif, the looping pre-to-post transition, for the "
                "plan view (or for each of --views if given)");
  cmd->add_option("--frames", a->frames, "frames of each --animation (2..600)")
      ->capture_default_str();
  add_common_flags(cmd, common, true);
  cmd->callback([&common, &action, a, views] {
    a->views_given = views->count() > 0;
    action = [&common, a] { run_render(*a, common); };
  });
}

}  // namespace caps::cli

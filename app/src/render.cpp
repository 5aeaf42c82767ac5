#include "caps/app/render.hpp"

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/fem/result_io.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/render/drawn_skin.hpp"
#include "caps/render/gltf_export.hpp"
#include "caps/render/overlay.hpp"
#include "caps/render/render.hpp"
#include "caps/render/simulation_report.hpp"
#include "caps/render/skin_surface.hpp"
#include "caps/surface/patient_model.hpp"
#include "json_fields.hpp"
#include "output_check.hpp"

CAPS_APP_REQUEST_JSON(caps::app::RenderRequest)
CAPS_APP_RESULT_JSON(caps::app::RenderResult)

namespace caps::app {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

std::vector<render::View> parse_views(const std::string& list) {
  std::vector<render::View> views;
  std::stringstream in(list);
  for (std::string v; std::getline(in, v, ',');) views.push_back(render::parse_view(v));
  if (views.empty()) throw InvalidInput("--views: name at least one of front,oblique,side,plan");
  return views;
}

void check(const RenderRequest& r) {
  if (r.image_size < 16 || r.image_size > 8192)
    throw InvalidInput(cat("--image-size ", r.image_size, ": expected 16..8192 pixels"));
  if (r.frames < 2 || r.frames > 600)
    throw InvalidInput(cat("--frames ", r.frames, ": expected 2..600"));
  if (!(r.tension_max_kpa >= 0) || !std::isfinite(r.tension_max_kpa))
    throw InvalidInput(cat("--tension-max-kpa ", r.tension_max_kpa,
                           ": expected a positive stress in kPa (0 = the 99th percentile)"));
  if (r.tension_max_kpa > 0 && !r.tension_map)
    throw InvalidInput("--tension-max-kpa sets the scale of --tension-map; add --tension-map");
}

}  // namespace

RenderResult run_render(const RenderRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  const std::vector<render::View> views = parse_views(r.views.empty() ? "front,oblique,side,plan" : r.views);
  check(r);
  Progress progress(reporter, "rendering", 4);
  const fem::Mesh mesh = fem::read_mesh_dir(r.result);
  const Eigen::MatrixX3d u = fem::read_result_displacement(r.result, mesh.n_nodes());
  const PatientModel model = PatientModel::load(r.model);
  const int n = r.subdivisions > 0 ? r.subdivisions
                                   : render::full_resolution_subdivisions(model, mesh);
  const render::DrawnSkin drawn = render::load_drawn_skin(model, r.model, reporter);
  const render::SkinSurfaces skin = render::displaced_skin(model, mesh, &u, n, &drawn);
  progress.update(1);
  const auto [fill_pre_mm2, fill_post_mm2] = render::wound_fill_area_mm2(skin);
  OutputDirectory out(r.output, r.force);
  render::RenderOptions o;
  o.width = o.height = r.image_size;
  render::Overlays overlays;
  overlays.suture_lines = true;
  overlays.scale_bar = true;
  if (r.displacement_map) overlays.scalar_maps.push_back(render::displacement_map(skin));
  if (r.tension_map)
    overlays.scalar_maps.push_back(render::tension_map(
        skin, mesh, fem::read_result_max_principal(r.result, mesh.n_nodes()), r.tension_max_kpa));
  if (!r.plan.empty()) overlays.plan_lines = render::plan_lines(plan::read_plan(r.plan), model);
  const auto files = render::render_views_with_overlays(model, skin, views, o, overlays, out.path(),
                                                         reporter);
  progress.update(2);
  if (r.gltf) render::write_gltf(skin, out.path() / "skin.glb");
  std::vector<fs::path> gifs;
  if (r.animation) {  // of the plan view unless views were named
    gifs = render::write_transition_gifs(model, skin,
                                         r.views.empty() ? std::vector{render::View::Plan} : views,
                                         o, r.frames, out.path());
  }
  progress.update(3);
  out.commit();
  progress.done();
  RenderResult s;
  s.output = r.output;
  s.skin_elements = static_cast<int>(skin.skin_elements.size());
  s.subdivisions = n;
  s.micropolygon_vertices = static_cast<int>(skin.n_micropolygon_vertices);
  s.triangles = static_cast<int>(skin.pre.F.rows());
  s.max_displacement_mm = u.rows() ? u.rowwise().norm().maxCoeff() : 0.0;
  s.wound_area_pre_mm2 = fill_pre_mm2;
  s.wound_area_post_mm2 = fill_post_mm2;
  for (const auto& f : files) s.images.push_back(f.filename().string());
  for (const auto& m : overlays.scalar_maps)
    if (m.name == "tension") {  // over the micropolygons (the range mesh is 0 by definition)
      s.has_tension = true;
      s.max_skin_tension_kpa = m.value.head(skin.n_micropolygon_vertices).maxCoeff();
      s.min_skin_tension_kpa = m.value.head(skin.n_micropolygon_vertices).minCoeff();
      s.tension_scale_max_kpa = m.max_value;
    }
  s.gltf = r.gltf;
  for (const auto& f : gifs) s.animations.push_back(f.filename().string());
  s.frames = r.animation ? r.frames : 0;
  s.warnings = mesh.warnings;
  return s;
}

std::string summary(const RenderResult& s) {
  return cat("caps render: ", s.images.size(), " images", s.gltf ? ", skin.glb" : "",
             s.animations.empty() ? std::string() : cat(", ", s.animations.size(), " animations"),
             " in ", s.output, " (", s.skin_elements, " skin faces, ", s.micropolygon_vertices,
             " micropolygon vertices)");
}

}  // namespace caps::app

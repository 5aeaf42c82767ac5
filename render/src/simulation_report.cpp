#include "caps/render/simulation_report.hpp"

#include "caps/render/overlay.hpp"

#include <cmath>
#include <cstdio>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/image/image_io.hpp"
#include "caps/surface/patient_model.hpp"

#include "html_text.hpp"

namespace fs = std::filesystem;

namespace caps::render {
namespace {

using detail::fmt;
using detail::html_escape;

// The warnings as a highlighted list (empty when there are none).
std::string warnings_html(const std::vector<std::string>& warnings) {
  if (warnings.empty()) return "";
  std::string html = "<div class=\"warnings\"><b>Warnings</b><ul>\n";
  for (const std::string& w : warnings) html += "<li>" + html_escape(w) + "</li>\n";
  return html + "</ul></div>\n";
}

double triangle_area(const TriMesh& m, Eigen::Index f) {
  const Eigen::Vector3d p0 = m.V.row(m.F(f, 0)), p1 = m.V.row(m.F(f, 1)), p2 = m.V.row(m.F(f, 2));
  return 0.5 * (p1 - p0).cross(p2 - p0).norm();
}

}  // namespace

std::pair<double, double> wound_fill_area_mm2(const SkinSurfaces& skin) {
  double pre = 0, post = 0;
  for (Eigen::Index f = 0; f < skin.pre.F.rows(); ++f) {
    if (skin.face_part[f] != SkinPart::WoundFill) continue;
    pre += triangle_area(skin.pre, f);
    post += triangle_area(skin.post, f);
  }
  return {pre, post};
}

SkinSurfaces simulated_skin(const PatientModel& model, const closure::Simulation& sim,
                            const DrawnSkin* drawn) {
  // The whole face where it was solved: the patch's elements carry the micropolygons, the
  // tissue model's skin nodes move the rest (displaced_skin()).
  const fem::Mesh& mesh = sim.face ? sim.face->mesh : sim.wound.continuum.mesh;
  return displaced_skin(model, mesh, sim.face ? &sim.face_result : &sim.result,
                        full_resolution_subdivisions(model, sim.wound.continuum.mesh), drawn);
}

ScalarMap simulated_tension_map(const SkinSurfaces& skin, const closure::Simulation& sim) {
  return sim.face ? tension_map(skin, sim.face->mesh, sim.face_result.max_principal_mpa)
                  : tension_map(skin, sim.wound.continuum.mesh, sim.result.max_principal_mpa);
}

namespace {

Overlays simulation_overlays(const PatientModel& model, const SimulationPictures& pictures) {
  Overlays overlays;
  if (pictures.plan) overlays.plan_lines = plan_lines(*pictures.plan, model);
  overlays.suture_lines = true;
  overlays.scale_bar = true;
  return overlays;
}

}  // namespace

std::vector<fs::path> render_simulation(const PatientModel& model, const closure::Simulation& sim,
                                        const std::vector<View>& views, const RenderOptions& options,
                                        const fs::path& dir, const SimulationPictures& pictures,
                                        Reporter* reporter) {
  Progress progress(reporter, "rendering the skin", 2);
  const SkinSurfaces skin = simulated_skin(model, sim, pictures.drawn);
  progress.update(1);
  Overlays overlays = simulation_overlays(model, pictures);
  if (pictures.tension_map)
    overlays.scalar_maps.push_back(simulated_tension_map(skin, sim));
  return render_views_with_overlays(model, skin, views, options, overlays, dir, reporter);
}

void write_comparison_report(const study::Comparison& c, const PatientModel& model,
                             const closure::SimulateOptions& options, const fs::path& dir,
                             const std::string& plan_name, const RenderOptions& render_options,
                             Reporter* reporter, const SimulationPictures& pictures) {
  fs::create_directories(dir / "measured");
  fs::create_directories(dir / "constant");
  fs::create_directories(dir / "layers");
  closure::SimulateOptions constant = options;
  constant.continuum.constant_thickness_mm = c.constant_thickness_mm;
  closure::SimulateOptions layered = options;
  layered.continuum.tissue = c.layered.wound.continuum.tissue;
  const bool has_layers = c.layered.wound.continuum.tissue == mesher::TissueLayers::Measured;
  const std::string layers_label = has_layers ? "measured layers" : "one material (no layers)";
  closure::write_simulation(c.measured, model, options, dir / "measured", plan_name + ", measured thickness");
  closure::write_simulation(c.constant, model, constant, dir / "constant", plan_name + ", constant thickness");
  closure::write_simulation(c.layered, model, layered, dir / "layers", plan_name + ", " + layers_label);
  const std::vector<View> views{View::Plan, View::Oblique};
  SimulationPictures plain = pictures;
  plain.tension_map = false;
  const Overlays overlays = simulation_overlays(model, plain);
  const SkinSurfaces measured_skin = simulated_skin(model, c.measured, pictures.drawn);
  const SkinSurfaces constant_skin = simulated_skin(model, c.constant, pictures.drawn);
  render_views_with_overlays(model, measured_skin, views, render_options, overlays,
                             dir / "measured", reporter);
  render_views_with_overlays(model, constant_skin, views, render_options, overlays,
                             dir / "constant", reporter);
  render_views_with_overlays(model, simulated_skin(model, c.layered, pictures.drawn), views,
                             render_options, overlays, dir / "layers", reporter);
  // The difference: both simulations mesh the same surface, so their skins have the same
  // vertices; each vertex of the measured skin is coloured by how far the constant-thickness
  // closure put it from the measured one.
  std::string difference_html;
  if (measured_skin.post.V.rows() == constant_skin.post.V.rows() &&
      measured_skin.pre.V.isApprox(constant_skin.pre.V)) {
    ScalarMap diff;
    diff.name = "difference";
    diff.value = (measured_skin.post.V - constant_skin.post.V).rowwise().norm();
    diff.max_value = scale_top(diff.value, 0);
    diff.unit = "mm";
    diff.title = "|measured - constant|\nafter the closure, mm";
    const Camera cam = standard_camera(View::Plan, model, measured_skin, render_options.width,
                                       render_options.height);
    RgbImage img = render_skin(measured_skin, 1.0, scalar_colors(diff.value, diff.max_value), cam,
                               render_options);
    draw_suture_lines(img, cam, suture_lines(measured_skin));
    draw_color_bar(img, diff.max_value, diff.unit, diff.title);
    draw_scale_bar(img, cam);
    write_png(dir / "difference_plan.png", img);
    difference_html = "<h2>Where the two closures differ</h2>\n<p>The skin after the closure (measured "
                      "thickness), coloured by the distance between the two post-operative skins: "
                      "largest " + fmt(diff.max_value, 2) + " mm.</p>\n<img src=\"difference_plan.png\" "
                      "alt=\"difference\" style=\"max-width:49%\">\n";
  } else {
    difference_html = "<p>No difference image: the two skins were not meshed alike.</p>\n";
  }
  write_text_atomic(dir / "comparison.json", study::comparison_json(c, plan_name) + "\n");

  const auto& a = c.measured_summary;
  const auto& b = c.constant_summary;
  const auto& l = c.layered_summary;
  // The two differences: measured against the constant thickness, and the measured layers
  // against the measured thickness (one material), each relative to the second.
  auto row = [&](const std::string& what, const std::string& unit, double x, double y, double z,
                 int d = 2) {
    const auto percent = [](double p, double q) {
      return q != 0 ? fmt(100.0 * (p - q) / std::abs(q), 1) + " %" : std::string();
    };
    return "<tr><td>" + what + "</td><td>" + unit + "</td><td>" + fmt(x, d) + "</td><td>" +
           fmt(y, d) + "</td><td>" + fmt(z, d) + "</td><td>" + percent(x, y) + "</td><td>" +
           percent(z, x) + "</td></tr>\n";
  };
  const std::string spacing = fmt(c.measured.sutures.spacing_mm, 1);
  // One picture per column: measured thickness, constant thickness, measured layers.
  auto pair = [&](const std::string& title, const std::string& image) {
    std::string out = "<h2>" + title + "</h2>\n<div class=\"pair\">";
    for (const auto& [folder, label] : {std::pair<std::string, std::string>{"measured", "measured thickness"},
                                        {"constant", "constant thickness"},
                                        {"layers", layers_label}})
      out += "<div><p>" + label + "</p><img src=\"" + folder + "/" + image + "\" alt=\"" + title +
             ", " + label + "\"></div>";
    return out + "</div>\n";
  };
  const std::string html =
      "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>caps compare: " +
      plan_name +
      "</title>\n<style>body{font-family:DejaVu Sans,Arial,sans-serif;max-width:1100px;margin:2em "
      "auto;color:#222}table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:4px "
      "10px;text-align:right}td:first-child,th:first-child{text-align:left}img{max-width:100%;"
      "border:1px solid #ddd}.pair{display:flex;gap:12px}.pair div{flex:1}.warnings{background:#fff4d6;border:1px solid #e0b000;padding:4px "
      "12px;margin:1em 0}</style></head><body>\n"
      "<h1>Measured thickness, constant thickness and measured tissue layers</h1>\n<p>The plan <b>" + plan_name +
      "</b> simulated on the same skin twice: with the thickness measured in the patient's volume, "
      "and with a constant " + fmt(c.constant_thickness_mm, 1) +
      " mm (the median measured under the wound, unless given), the assumption the 1992 CAPS system "
      "made for surface scans; and a third time with the measured thickness divided into the "
      "measured dermis, subcutaneous fat and deep tissue, each with its own material (" +
      (has_layers ? std::string("measured layers")
                  : std::string("this model has no measured layers under the wound: one material")) +
      "). All use the same surface mesh, so the results differ only in depth and tissue. The "
      "material model and the wound closed by suture constraints: docs/fem.md.</p>\n" +
      warnings_html(c.warnings) +
      "<table><tr><th>quantity</th><th>unit</th><th>measured</th><th>constant</th><th>" +
      layers_label + "</th><th>measured vs constant</th><th>" + layers_label +
      " vs measured</th></tr>\n" +
      row("thickness under the wound, mean", "mm", a.thickness_mean_mm, b.thickness_mean_mm,
          l.thickness_mean_mm) +
      row("thickness under the wound, min", "mm", a.thickness_min_mm, b.thickness_min_mm,
          l.thickness_min_mm) +
      row("thickness under the wound, max", "mm", a.thickness_max_mm, b.thickness_max_mm,
          l.thickness_max_mm) +
      row("largest skin displacement", "mm", a.max_displacement_mm, b.max_displacement_mm,
          l.max_displacement_mm) +
      row("mean skin displacement near the wound", "mm", a.mean_displacement_mm,
          b.mean_displacement_mm, l.mean_displacement_mm) +
      row("closing force across the wound", "N", a.closing_force_n, b.closing_force_n,
          l.closing_force_n) +
      row("largest force on one suture (sutures every " + spacing + " mm, as caps simulate)",
          "N", a.max_suture_at_spacing_n, b.max_suture_at_spacing_n, l.max_suture_at_spacing_n) +
      row("largest force on one nodal suture pair (one node of one depth)", "N",
          a.max_suture_force_n, b.max_suture_force_n, l.max_suture_force_n) +
      row("largest skin tension (max principal stress)", "kPa", a.max_skin_tension_kpa,
          b.max_skin_tension_kpa, l.max_skin_tension_kpa, 1) +
      row("strain energy", "mJ", a.strain_energy_mj, b.strain_energy_mj, l.strain_energy_mj) +
      "</table>\n" +
      pair("After the closure, looking at the wound", "post_plan.png") +
      pair("After the closure, oblique", "post_oblique.png") + difference_html +
      "<h2>Before (the same for all)</h2>\n<img src=\"measured/pre_plan.png\" alt=\"before\" "
      "style=\"max-width:49%\">\n" + pair("Cross-sections", "section.png") +
      "<h2>Surface mesh (the same for all)</h2>\n<img src=\"measured/surface.png\" alt=\"surface "
      "mesh\">\n<p>Files: measured/, constant/ and layers/ hold mesh.vtu, result.vtu (ParaView), mesh.inp "
      "(CalculiX), result.json and the pictures; comparison.json holds this table.</p>\n"
      "</body></html>\n";
  write_text_atomic(dir / "report.html", html);
}

}  // namespace caps::render

#include "caps/render/model_comparison_report.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <unordered_map>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/image/canvas.hpp"
#include "caps/image/image_io.hpp"
#include "caps/render/overlay.hpp"
#include "caps/render/simulation_report.hpp"
#include "caps/surface/patient_model.hpp"

#include "html_text.hpp"

namespace fs = std::filesystem;

namespace caps::render {
namespace {

using detail::fmt;
using detail::html_escape;

// Nearest vertex queries on a uniform grid of `cell` mm buckets (the skins' micropolygons are
// about 0.5 mm apart, so a query looks at 27 buckets of a few vertices each).
class VertexGrid {
 public:
  // The vertices v of V with keep(v).
  template <class Keep>
  VertexGrid(const Eigen::MatrixX3d& V, double cell, Keep keep) : V_(V), cell_(cell) {
    for (Eigen::Index v = 0; v < V.rows(); ++v)
      if (keep(v)) buckets_[key(cell_of(V.row(v).transpose()))].push_back(v);
  }
  // The nearest vertex within `radius` (<= cell), or -1.
  Eigen::Index nearest(const Eigen::Vector3d& p, double radius) const {
    const Eigen::Vector3i c = cell_of(p);
    Eigen::Index best = -1;
    double best_d2 = radius * radius;
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = buckets_.find(key(c + Eigen::Vector3i(dx, dy, dz)));
          if (it == buckets_.end()) continue;
          for (Eigen::Index v : it->second) {
            const double d2 = (V_.row(v).transpose() - p).squaredNorm();
            if (d2 <= best_d2) {
              best_d2 = d2;
              best = v;
            }
          }
        }
    return best;
  }

 private:
  Eigen::Vector3i cell_of(const Eigen::Vector3d& p) const {
    return (p / cell_).array().floor().cast<int>();
  }
  static long long key(const Eigen::Vector3i& c) {
    return (static_cast<long long>(c.x() & 0x1FFFFF) << 42) | (static_cast<long long>(c.y() & 0x1FFFFF) << 21) |
           static_cast<long long>(c.z() & 0x1FFFFF);
  }
  const Eigen::MatrixX3d& V_;  // not owned; must outlive the grid
  double cell_;
  std::unordered_map<long long, std::vector<Eigen::Index>> buckets_;
};

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  const std::size_t i = std::min(v.size() - 1, static_cast<std::size_t>(q * (v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + i, v.end());
  return v[i];
}

// The skin's tension at its vertices (kPa), as the tension map shows it.
Eigen::VectorXd skin_tension_kpa(const SkinSurfaces& skin, const closure::Simulation& sim) {
  return simulated_tension_map(skin, sim).value;
}

}  // namespace

SkinDifference skin_difference(const SkinSurfaces& reference, const Eigen::VectorXd& reference_tension_kpa,
                               const SkinSurfaces& other, const Eigen::VectorXd& other_tension_kpa,
                               const Eigen::Matrix4d& T, double match_mm) {
  const Eigen::Index n = reference.pre.V.rows();
  if (reference_tension_kpa.size() != n || other_tension_kpa.size() != other.pre.V.rows())
    throw InvalidInput("skin_difference: a tension field does not have one value per skin vertex");
  if (!(match_mm > 0)) throw InvalidInput(cat("skin_difference: match distance ", match_mm, " mm must be > 0"));
  const Eigen::Matrix3d A = T.topLeftCorner<3, 3>();
  if (!T.allFinite() || !(A.determinant() > 0))
    throw InvalidInput("skin_difference: the transform must be a finite similarity");
  const Eigen::Matrix3d A_inv = A.inverse();
  // A vertex on the finite elements is matched to one on the other's elements, a vertex of the
  // range mesh to one of its range mesh: where the two skins' patches overlap the other's range
  // vertices at their rims (which do not move) would otherwise stand in for its moving skin.
  const auto on_mesh = [&](Eigen::Index v) { return other.vertex_element[v] >= 0; };
  const VertexGrid mesh_grid(other.pre.V, match_mm, on_mesh);
  const VertexGrid range_grid(other.pre.V, match_mm, [&](Eigen::Index v) { return !on_mesh(v); });
  SkinDifference d;
  d.displacement_mm = Eigen::VectorXd::Zero(n);
  d.tension_kpa = Eigen::VectorXd::Zero(n);
  d.matched.assign(n, 0);
  std::vector<double> abs_tension;
  for (Eigen::Index v = 0; v < n; ++v) {
    const Eigen::Vector3d p = reference.pre.V.row(v).transpose();
    const Eigen::Vector3d q = A * p + T.topRightCorner<3, 1>();
    Eigen::Index w = reference.vertex_element[v] >= 0 ? mesh_grid.nearest(q, match_mm) : range_grid.nearest(q, match_mm);
    if (w < 0) w = reference.vertex_element[v] >= 0 ? range_grid.nearest(q, match_mm) : mesh_grid.nearest(q, match_mm);
    if (w < 0) continue;
    d.matched[v] = 1;
    const Eigen::Vector3d u_ref = (reference.post.V.row(v) - reference.pre.V.row(v)).transpose();
    const Eigen::Vector3d u_other = A_inv * (other.post.V.row(w) - other.pre.V.row(w)).transpose();
    d.displacement_mm[v] = (u_other - u_ref).norm();
    d.tension_kpa[v] = other_tension_kpa[w] - reference_tension_kpa[v];
    d.max_displacement_mm = std::max(d.max_displacement_mm, d.displacement_mm[v]);
    if (reference.vertex_element[v] >= 0) abs_tension.push_back(std::abs(d.tension_kpa[v]));
  }
  d.p99_abs_tension_kpa = percentile(abs_tension, 0.99);
  return d;
}

void write_model_comparison_report(const study::ModelComparison& c,
                                   const std::vector<const PatientModel*>& models,
                                   const closure::SimulateOptions& options, const fs::path& dir,
                                   const std::string& plan_name, const RenderOptions& ro,
                                   Reporter* reporter) {
  if (c.sides.empty() || models.size() != c.sides.size())
    throw InvalidInput("model comparison report: one model per side is needed");
  Progress progress(reporter, "drawing the comparison", static_cast<double>(2 * c.sides.size()));
  std::vector<SkinSurfaces> skins;
  std::vector<Eigen::VectorXd> tensions;
  for (std::size_t i = 0; i < c.sides.size(); ++i) {
    const auto& side = c.sides[i];
    const PatientModel& model = *models[i];
    fs::create_directories(dir / side.key);
    closure::write_simulation(side.simulation, model, options, dir / side.key, plan_name + ", " + side.label);
    skins.push_back(simulated_skin(model, side.simulation));
    tensions.push_back(skin_tension_kpa(skins.back(), side.simulation));
    Overlays overlays;
    overlays.plan_lines = plan_lines(side.plan, model);
    overlays.suture_lines = true;
    overlays.scale_bar = true;
    render_views_with_overlays(model, skins.back(), {View::Plan}, ro, overlays, dir / side.key, reporter);
    progress.update(static_cast<double>(i + 1));
  }
  // The differences on the reference's skin, one colour scale for every side.
  std::vector<SkinDifference> diffs;
  double top_mm = 0, top_kpa = 0;
  for (std::size_t i = 1; i < c.sides.size(); ++i) {
    diffs.push_back(skin_difference(skins[0], tensions[0], skins[i], tensions[i], c.sides[i].reference_to_model));
    top_mm = std::max(top_mm, diffs.back().max_displacement_mm);
    top_kpa = std::max(top_kpa, diffs.back().p99_abs_tension_kpa);
  }
  top_mm = top_mm > 0 ? top_mm : 1.0;
  top_kpa = top_kpa > 0 ? top_kpa : 1.0;
  const Camera cam = standard_camera(View::Plan, *models[0], skins[0], ro.width, ro.height);
  const auto lines = suture_lines(skins[0]);
  const std::string& ref = c.sides[0].label;
  auto unmatched_grey = [&](Eigen::MatrixX3d colours, const SkinDifference& d) {
    for (Eigen::Index v = 0; v < colours.rows(); ++v)
      if (!d.matched[v]) colours.row(v) << 0.55, 0.55, 0.55;
    return colours;
  };
  std::string difference_html;
  for (std::size_t i = 1; i < c.sides.size(); ++i) {
    const SkinDifference& d = diffs[i - 1];
    const std::string& key = c.sides[i].key;
    RgbImage a = render_skin(skins[0], 1.0, unmatched_grey(scalar_colors(d.displacement_mm, top_mm), d), cam, ro);
    draw_suture_lines(a, cam, lines);
    draw_color_bar(a, top_mm, "mm", "|u(" + c.sides[i].label + ")\n - u(" + ref + ")|");
    draw_scale_bar(a, cam);
    write_png(dir / ("difference_" + key + "_displacement.png"), a);
    RgbImage b = render_skin(skins[0], 1.0, unmatched_grey(signed_colors(d.tension_kpa, top_kpa), d), cam, ro);
    draw_suture_lines(b, cam, lines);
    draw_signed_color_bar(b, top_kpa, "kPa", "tension(" + c.sides[i].label + ")\n - tension(" + ref + ")");
    draw_scale_bar(b, cam);
    write_png(dir / ("difference_" + key + "_tension.png"), b);
    difference_html += "<h3>" + html_escape(c.sides[i].label) + " against " + html_escape(ref) +
                       "</h3>\n<p>largest displacement difference " + fmt(d.max_displacement_mm, 2) +
                       " mm; tension difference up to " + fmt(d.p99_abs_tension_kpa, 1) +
                       " kPa (99th percentile of |difference| on the mesh)</p>\n<div class=\"pair\"><div>"
                       "<img src=\"difference_" + key + "_displacement.png\" alt=\"displacement difference\">"
                       "</div><div><img src=\"difference_" + key + "_tension.png\" alt=\"tension "
                       "difference\"></div></div>\n";
    progress.update(static_cast<double>(c.sides.size() + i));
  }
  write_text_atomic(dir / "model_comparison.json", study::model_comparison_json(c, plan_name) + "\n");

  std::string head = "<tr><th>quantity</th><th>unit</th>";
  for (const auto& s : c.sides) head += "<th>" + html_escape(s.label) + "</th>";
  for (std::size_t i = 1; i < c.sides.size(); ++i) head += "<th>" + html_escape(c.sides[i].label) + " vs " + html_escape(ref) + "</th>";
  head += "</tr>\n";
  auto row = [&](const std::string& what, const std::string& unit, auto get, int digits = 2) {
    std::string r = "<tr><td>" + what + "</td><td>" + unit + "</td>";
    for (const auto& s : c.sides) r += "<td>" + fmt(get(s.summary), digits) + "</td>";
    const double base = get(c.sides[0].summary);
    for (std::size_t i = 1; i < c.sides.size(); ++i)
      r += "<td>" + (base != 0 ? fmt(100.0 * (get(c.sides[i].summary) - base) / std::abs(base), 1) + " %" : std::string()) + "</td>";
    return r + "</tr>\n";
  };
  using S = study::SimulationSummary;
  std::string table = "<table>" + head +
      row("closing force across the wound", "N", [](const S& s) { return s.closing_force_n; }) +
      row("largest force on one suture (sutures every " + fmt(c.sides[0].simulation.sutures.spacing_mm, 1) +
          " mm, as caps simulate)", "N", [](const S& s) { return s.max_suture_at_spacing_n; }) +
      row("largest force on one nodal suture pair (one node of one depth)", "N",
          [](const S& s) { return s.max_suture_force_n; }) +
      row("peak skin tension (max principal stress)", "kPa", [](const S& s) { return s.max_skin_tension_kpa; }, 1) +
      row("largest skin displacement", "mm", [](const S& s) { return s.max_displacement_mm; }) +
      row("mean skin displacement near the wound", "mm", [](const S& s) { return s.mean_displacement_mm; }) +
      row("thickness under the wound, mean", "mm", [](const S& s) { return s.thickness_mean_mm; }) +
      row("thickness under the wound, min", "mm", [](const S& s) { return s.thickness_min_mm; }) +
      row("thickness under the wound, max", "mm", [](const S& s) { return s.thickness_max_mm; }) +
      row("strain energy", "mJ", [](const S& s) { return s.strain_energy_mj; }) + "</table>\n";
  std::string placement = "<table><tr><th>model</th><th>theta (deg)</th><th>z (mm)</th><th>orientation "
                          "(deg)</th><th>centre gap (mm)</th></tr>\n";
  for (const auto& s : c.sides)
    placement += "<tr><td>" + html_escape(s.label) + "</td><td>" + fmt(s.plan.frame.theta_deg, 2) + "</td><td>" +
                 fmt(s.plan.frame.z_mm, 2) + "</td><td>" + fmt(s.plan.frame.orientation_deg, 2) + "</td><td>" +
                 fmt(s.centre_gap_mm, 2) + "</td></tr>\n";
  placement += "</table>\n";
  std::string after = "<div class=\"pair\">";
  for (const auto& s : c.sides)
    after += "<div><p>" + html_escape(s.label) + "</p><img src=\"" + s.key + "/post_plan.png\" alt=\"" +
             html_escape(s.label) + "\"></div>";
  after += "</div>\n";
  std::string warnings;
  if (!c.warnings.empty()) {
    warnings = "<div class=\"warnings\"><b>Warnings</b><ul>\n";
    for (const auto& w : c.warnings) warnings += "<li>" + html_escape(w) + "</li>\n";
    warnings += "</ul></div>\n";
  }
  const std::string html =
      "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>caps compare-models: " +
      html_escape(plan_name) +
      "</title>\n<style>body{font-family:DejaVu Sans,Arial,sans-serif;max-width:1400px;margin:2em "
      "auto;color:#222}table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:4px "
      "10px;text-align:right}td:first-child,th:first-child{text-align:left}img{max-width:100%;border:1px "
      "solid #ddd}.pair{display:flex;gap:12px}.pair div{flex:1}.warnings{background:#fff4d6;border:1px "
      "solid #e0b000;padding:4px 12px;margin:1em 0}</style></head><body>\n"
      "<h1>One plan on the patient's models</h1>\n<p>The plan <b>" + html_escape(plan_name) +
      "</b> placed at the same anatomical point and direction on each model (carried from the " +
      html_escape(ref) + " model's frame by the registration) and simulated with each model's "
      "own skin and thickness: the scan-built model assumes a constant thickness (the 1992 CAPS "
      "way), the CT model measures it, the fused model has the CT's depths under the scan's skin "
      "and colour. Linear elasticity; the wound closed by suture constraints (docs/fem.md).</p>\n" +
      warnings + table + "<h2>Where the plan was placed</h2>\n" + placement +
      "<h2>After the closure, looking at the wound</h2>\n" + after +
      "<h2>Where the results differ (on the " + html_escape(ref) + " model's skin after the closure)</h2>\n"
      "<p>Left: the distance between the displacements (mm); right: the difference in skin tension "
      "(kPa; red where the other model is more tense). One colour scale for every model; grey where "
      "the other model's skin has no point within 2 mm.</p>\n" + difference_html +
      "<p>Files: each model's folder holds mesh.vtu, result.vtu, mesh.inp, result.json and the "
      "pictures; model_comparison.json holds the table.</p>\n</body></html>\n";
  write_text_atomic(dir / "report.html", html);
  progress.done();
}

}  // namespace caps::render

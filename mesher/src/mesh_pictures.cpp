#include "caps/mesher/mesh_pictures.hpp"

#include "caps/mesher/continuum_mesher.hpp"

#include "caps/core/error.hpp"
#include "caps/image/canvas.hpp"
#include "caps/surface/patient_model.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

namespace caps::mesher {

using namespace caps::fem;
namespace {

namespace fs = std::filesystem;

using V2 = Eigen::Vector2d;

void text(Canvas& cv, double x, double y, const std::string& s, double size) {
  cv.text(x, y, s, {.size_px = size});
}

/// World (mm) to pixels in a square panel, y up.
struct Panel {
  double x0, y0, size_px, cx, cy, half_mm;
  double px(double x) const { return x0 + size_px / 2 + (x - cx) / half_mm * size_px / 2; }
  double py(double y) const { return y0 + size_px / 2 - (y - cy) / half_mm * size_px / 2; }
};

void draw_panel(Canvas& cv, const SurfaceMesh& s, const Panel& p, const std::string& label) {
  auto at = [&](int v) { return V2(p.px(s.xy_mm(v, 0)), p.py(s.xy_mm(v, 1))); };
  cv.push_clip(p.x0, p.y0, p.size_px, p.size_px);
  for (std::size_t k = 0; k < s.polygons.size(); ++k) {
    const auto& poly = s.polygons[k];
    std::vector<V2> corners;
    for (int v : poly) corners.push_back(at(v));
    Eigen::Vector3d fill(1, 1, 1);
    if (s.polygon_stage[k] == 1)
      fill = {1.0, 0.72, 0.45};
    else if (s.polygon_expanded[k])
      fill = {0.62, 0.78, 1.0};
    else if (poly.size() == 3)
      fill = {0.85, 0.85, 0.85};
    cv.fill_polygon(corners, fill);
    cv.polyline(corners, {.colour = {0.25, 0.25, 0.25}, .width_px = 0.8}, true);
  }
  // The wound border (the incision lines) in bold.
  for (const auto& chain : s.edge_chain)
    cv.line(at(chain.front()), at(chain.back()), {.colour = {0.75, 0, 0}, .width_px = 3.0});
  cv.pop_clip();
  cv.stroke_rect(p.x0 - 0.5, p.y0 - 0.5, p.size_px + 1, p.size_px + 1);
  // A scale bar of a round length near a fifth of the panel.
  const double target = p.half_mm * 0.4;
  const double mag = std::pow(10.0, std::floor(std::log10(target)));
  const double bar = target / mag >= 5 ? 5 * mag : (target / mag >= 2 ? 2 * mag : mag);
  const double bx = p.x0 + 12, by = p.y0 + p.size_px - 14;
  cv.line(V2(bx, by), V2(bx + bar / p.half_mm * p.size_px / 2, by), {.width_px = 3});
  text(cv, bx, by - 6, cat(bar, " mm"), 12);
  text(cv, p.x0, p.y0 - 8, label, 13);
}

}  // namespace

void write_surface_mesh_png(const fs::path& path, const SurfaceMesh& s, const std::string& title) {
  if (s.n_vertices() == 0) throw InvalidInput("surface picture: the surface mesh is empty");
  const double panel = 620, margin = 40, top = 70, bottom = 56;
  Canvas cv(static_cast<int>(3 * margin + 2 * panel), static_cast<int>(top + panel + bottom));
  double half = 0;
  for (int v = 0; v < s.n_vertices(); ++v)
    half = std::max(half, s.xy_mm.row(v).cwiseAbs().maxCoeff());
  draw_panel(cv, s, {margin, top, panel, 0, 0, half * 1.02},
             cat("whole mesh: ", s.n_layers, " layers, extent ", std::round(s.extent_mm), " mm",
                 s.trimmed_polygons + s.pulled_vertices > 0 ? ", trimmed to the model" : ""));
  draw_panel(cv, s, {2 * margin + panel, top, panel, 0, 0, std::max(0.9 * s.wound_size_mm, 1.0)},
             "around the wound");
  text(cv, margin, 28, title, 16);
  const auto& q = s.quality;
  text(cv, margin, top + panel + 24,
          cat(q.n_quads, " quads, ", q.n_triangles, " triangles; corner angles ",
              std::round(q.min_angle_deg), "-", std::round(q.max_angle_deg),
              " deg; edge ratio max ", std::round(q.max_aspect_ratio * 10) / 10, ", mean ",
              std::round(q.mean_aspect_ratio * 100) / 100,
              ".  Bold red: wound border; orange: stage-1 triangles; blue: expanded vertices; "
              "grey: split triangles"),
          12);
  text(cv, margin, top + panel + 44,
          cat("x: arc length (mm) at the wound's reference radius, increasing with theta (patient's "
              "left); y: z (mm, superior up)",
              s.trimmed_polygons + s.pulled_vertices > 0
                  ? cat(".  Trimmed to the model: ", s.trimmed_polygons, " polygons left out, ",
                        s.pulled_vertices, " first-layer vertices pulled back")
                  : std::string()),
          12);
  cv.write_png(path);
}

void write_cross_section_png(const fs::path& path, const SurfaceMesh& s, const PatientModel& model,
                             const ContinuumMeshOptions& o, const std::string& title,
                             double depth_scale) {
  if (s.n_vertices() == 0) throw InvalidInput("cross-section picture: the surface mesh is empty");
  // The element layers as the mesher lays them (uniform fractions, or the measured dermis, fat
  // and deep tissue).
  const LayerStack stack(s, model, o);
  const int NL = stack.n_layers();
  // Where the line y = 0 crosses polygon edges (element walls), and which x are covered.
  double xmin = 1e300, xmax = -1e300;
  std::vector<double> walls;
  auto covered = [&](double x) {
    for (const auto& poly : s.polygons) {
      bool inside = false;
      for (std::size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
        const double xi = s.xy_mm(poly[i], 0), yi = s.xy_mm(poly[i], 1);
        const double xj = s.xy_mm(poly[j], 0), yj = s.xy_mm(poly[j], 1);
        if ((yi > 0) != (yj > 0) && x < (xj - xi) * (0 - yi) / (yj - yi) + xi) inside = !inside;
      }
      if (inside) return true;
    }
    return false;
  };
  for (const auto& poly : s.polygons)
    for (std::size_t i = 0; i < poly.size(); ++i) {
      const Eigen::Vector2d a = s.xy_mm.row(poly[i]), b = s.xy_mm.row(poly[(i + 1) % poly.size()]);
      if ((a.y() > 0) == (b.y() > 0)) continue;
      const double x = a.x() + (b.x() - a.x()) * (0 - a.y()) / (b.y() - a.y());
      walls.push_back(x);
      xmin = std::min(xmin, x);
      xmax = std::max(xmax, x);
    }
  if (walls.empty()) throw InvalidInput("cross-section picture: the line z = z_c misses the mesh");
  auto theta_of = [&](double x) { return s.theta_c_deg + x / s.ref_radius_mm * 180 / std::numbers::pi; };
  auto depth_mm = [&](double x) {
    return o.constant_thickness_mm > 0 ? o.constant_thickness_mm : model.thickness(theta_of(x), s.z_c_mm);
  };
  double dmax = 0;
  for (int i = 0; i <= 200; ++i) dmax = std::max(dmax, depth_mm(xmin + (xmax - xmin) * i / 200));
  const double W = 1240, left = 60, right = 30, top = 86;
  const double sx = (W - left - right) / (xmax - xmin);
  const double sy = sx * depth_scale;
  const double plot_h = dmax * sy + 20;
  Canvas cv(static_cast<int>(W), static_cast<int>(top + plot_h + 80));
  auto X = [&](double x) { return left + (x - xmin) * sx; };
  // Depth below the skin (the skin drawn flat): the head's curvature would otherwise hide the
  // layers, which are what the picture is for. Y(depth): the pixel row of a depth (mm) below it.
  std::vector<double> D;  // the interface depths of one column (LayerStack::depths)
  auto Y = [&](double depth) { return top + 10 + depth * sy; };
  const int n = 1200;
  const int per = stack.per_tissue_layer();
  const Eigen::Vector3d fat_fill(1.0, 0.9, 0.55), tissue_line(0.75, 0.45, 0.0);
  // Runs of covered x: the stretches where the section crosses the mesh.
  std::vector<std::vector<double>> runs(1);
  for (int i = 0; i <= n; ++i) {
    const double x = xmin + (xmax - xmin) * i / n;
    if (covered(x)) runs.back().push_back(x);
    else if (!runs.back().empty()) runs.emplace_back();
  }
  for (const auto& run : runs) {
    if (run.size() < 2) continue;
    // Each sample's interfaces once: point i of interface k is at[i][k].
    std::vector<std::vector<V2>> at(run.size(), std::vector<V2>(NL + 1));
    for (std::size_t i = 0; i < run.size(); ++i) {
      stack.depths(theta_of(run[i]), s.z_c_mm, depth_mm(run[i]), D);
      for (int k = 0; k <= NL; ++k) at[i][k] = V2(X(run[i]), Y(D[k]));
    }
    if (stack.measured()) {
      // The subcutaneous fat, between its two interfaces, filled.
      std::vector<V2> band;
      for (std::size_t i = 0; i < run.size(); ++i) band.push_back(at[i][per]);
      for (std::size_t i = run.size(); i-- > 0;) band.push_back(at[i][2 * per]);
      cv.fill_polygon(band, fat_fill);
    }
    for (int k = 0; k <= NL; ++k) {
      const bool tissue = stack.measured() && (k == per || k == 2 * per);
      const Pen pen{.colour = k == 0 ? Eigen::Vector3d(0.1, 0.1, 0.1)
                              : k == NL ? Eigen::Vector3d(0.55, 0.35, 0.1)
                              : tissue ? tissue_line : Eigen::Vector3d(0.35, 0.35, 0.35),
                    .width_px = k == 0 ? 3.0 : (k == NL ? 2.5 : (tissue ? 1.8 : 1.0))};
      std::vector<V2> line;
      for (const auto& p : at) line.push_back(p[k]);
      cv.polyline(line, pen);
    }
  }
  const Eigen::Vector3d wall(0.35, 0.35, 0.35);
  for (double x : walls) {
    stack.depths(theta_of(x), s.z_c_mm, depth_mm(x), D);
    cv.line(V2(X(x), Y(D[0])), V2(X(x), Y(D[NL])), {.colour = wall});
    for (int k = 0; k <= NL; ++k) cv.fill_circle(V2(X(x), Y(D[k])), 2.0, wall);
  }
  text(cv, left, 28, title, 16);
  text(cv, left, 50,
          cat("section at z = ", std::round(s.z_c_mm * 10) / 10, " mm through the wound, skin drawn flat, depth below it x",
              depth_scale, "; ", NL, " layers, thickness ",
              o.constant_thickness_mm > 0 ? cat(o.constant_thickness_mm, " mm (constant)")
                                          : std::string("from the model")),
          12);
  text(cv, left, 68,
       stack.measured()
           ? "bold: skin (top) and bone (bottom); measured layers: dermis, subcutaneous fat "
             "(yellow, orange lines), deep tissue; dots: where the section meets element edges"
           : "bold: skin (top) and bone (bottom); uniform layers; dots: where the section meets "
             "element edges",
       12);
  text(cv, left, top + plot_h + 40,
          cat("arc length (mm) from ", std::round(xmin), " to ", std::round(xmax),
              " at the reference radius ", std::round(s.ref_radius_mm), " mm"),
          12);
  cv.write_png(path);
}

}  // namespace caps::mesher

#include "caps/fem/mesh_pictures.hpp"

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/surface/patient_model.hpp"

#include <cairo.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>
#include <vector>

namespace caps::fem {
namespace {

namespace fs = std::filesystem;

/// A white canvas with DejaVu text, written atomically as PNG.
struct Canvas {
  std::unique_ptr<cairo_surface_t, decltype(&cairo_surface_destroy)> surface{nullptr,
                                                                             cairo_surface_destroy};
  std::unique_ptr<cairo_t, decltype(&cairo_destroy)> cr{nullptr, cairo_destroy};
  Canvas(int w, int h) {
    surface.reset(cairo_image_surface_create(CAIRO_FORMAT_RGB24, w, h));
    cr.reset(cairo_create(surface.get()));
    cairo_set_source_rgb(cr.get(), 1, 1, 1);
    cairo_paint(cr.get());
    cairo_select_font_face(cr.get(), "DejaVu Sans", CAIRO_FONT_SLANT_NORMAL,
                           CAIRO_FONT_WEIGHT_NORMAL);
  }
  cairo_t* c() { return cr.get(); }
  void text(double x, double y, const std::string& s, double size, double align = 0) {
    cairo_set_font_size(c(), size);
    cairo_text_extents_t ext;
    cairo_text_extents(c(), s.c_str(), &ext);
    cairo_move_to(c(), x - align * ext.x_advance, y);
    cairo_set_source_rgb(c(), 0.1, 0.1, 0.1);
    cairo_show_text(c(), s.c_str());
  }
  void write(const fs::path& path) {
    cairo_surface_flush(surface.get());
    write_file_atomic(path, [&](const fs::path& tmp) {
      if (cairo_surface_write_to_png(surface.get(), tmp.c_str()) != CAIRO_STATUS_SUCCESS)
        throw IoError(cat(path.string(), ": cannot write PNG"));
    });
  }
};

/// World (mm) to pixels in a square panel, y up.
struct Panel {
  double x0, y0, size_px, cx, cy, half_mm;
  double px(double x) const { return x0 + size_px / 2 + (x - cx) / half_mm * size_px / 2; }
  double py(double y) const { return y0 + size_px / 2 - (y - cy) / half_mm * size_px / 2; }
};

void draw_panel(Canvas& cv, const SurfaceMesh& s, const Panel& p, const std::string& label) {
  cairo_t* c = cv.c();
  cairo_save(c);
  cairo_rectangle(c, p.x0, p.y0, p.size_px, p.size_px);
  cairo_clip(c);
  for (std::size_t k = 0; k < s.polygons.size(); ++k) {
    const auto& poly = s.polygons[k];
    for (std::size_t i = 0; i < poly.size(); ++i) {
      const double x = p.px(s.xy_mm(poly[i], 0)), y = p.py(s.xy_mm(poly[i], 1));
      i == 0 ? cairo_move_to(c, x, y) : cairo_line_to(c, x, y);
    }
    cairo_close_path(c);
    if (s.polygon_stage[k] == 1)
      cairo_set_source_rgb(c, 1.0, 0.72, 0.45);
    else if (s.polygon_expanded[k])
      cairo_set_source_rgb(c, 0.62, 0.78, 1.0);
    else if (poly.size() == 3)
      cairo_set_source_rgb(c, 0.85, 0.85, 0.85);
    else
      cairo_set_source_rgb(c, 1, 1, 1);
    cairo_fill_preserve(c);
    cairo_set_source_rgb(c, 0.25, 0.25, 0.25);
    cairo_set_line_width(c, 0.8);
    cairo_stroke(c);
  }
  // The wound border (the incision lines) in bold.
  cairo_set_source_rgb(c, 0.75, 0, 0);
  cairo_set_line_width(c, 3.0);
  for (const auto& chain : s.edge_chain) {
    cairo_move_to(c, p.px(s.xy_mm(chain.front(), 0)), p.py(s.xy_mm(chain.front(), 1)));
    cairo_line_to(c, p.px(s.xy_mm(chain.back(), 0)), p.py(s.xy_mm(chain.back(), 1)));
  }
  cairo_stroke(c);
  cairo_restore(c);
  cairo_set_source_rgb(c, 0.1, 0.1, 0.1);
  cairo_set_line_width(c, 1.0);
  cairo_rectangle(c, p.x0 - 0.5, p.y0 - 0.5, p.size_px + 1, p.size_px + 1);
  cairo_stroke(c);
  // A scale bar of a round length near a fifth of the panel.
  const double target = p.half_mm * 0.4;
  const double mag = std::pow(10.0, std::floor(std::log10(target)));
  const double bar = target / mag >= 5 ? 5 * mag : (target / mag >= 2 ? 2 * mag : mag);
  const double bx = p.x0 + 12, by = p.y0 + p.size_px - 14;
  cairo_move_to(c, bx, by);
  cairo_line_to(c, bx + bar / p.half_mm * p.size_px / 2, by);
  cairo_set_line_width(c, 3);
  cairo_stroke(c);
  cv.text(bx, by - 6, cat(bar, " mm"), 12);
  cv.text(p.x0, p.y0 - 8, label, 13);
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
             cat("whole mesh: ", s.n_layers, " layers, extent ", std::round(s.extent_mm), " mm"));
  draw_panel(cv, s, {2 * margin + panel, top, panel, 0, 0, std::max(0.9 * s.wound_size_mm, 1.0)},
             "around the wound");
  cv.text(margin, 28, title, 16);
  const auto& q = s.quality;
  cv.text(margin, top + panel + 24,
          cat(q.n_quads, " quads, ", q.n_triangles, " triangles; corner angles ",
              std::round(q.min_angle_deg), "-", std::round(q.max_angle_deg),
              " deg; edge ratio max ", std::round(q.max_aspect_ratio * 10) / 10, ", mean ",
              std::round(q.mean_aspect_ratio * 100) / 100,
              ".  Bold red: wound border; orange: stage-1 triangles; blue: expanded vertices; "
              "grey: split triangles"),
          12);
  cv.text(margin, top + panel + 44,
          "x: arc length (mm) at the wound's reference radius, increasing with theta (patient's "
          "left); y: z (mm, superior up)", 12);
  cv.write(path);
}

void write_cross_section_png(const fs::path& path, const SurfaceMesh& s, const PatientModel& model,
                             const ContinuumMeshOptions& o, const std::string& title,
                             double depth_scale) {
  if (s.n_vertices() == 0) throw InvalidInput("cross-section picture: the surface mesh is empty");
  const int NL = std::max(1, o.n_layers);
  std::vector<double> F(NL + 1, 0.0);
  for (int k = 0; k < NL; ++k) F[k + 1] = F[k] + std::pow(o.grading, k);
  for (double& f : F) f /= F[NL];
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
  const double W = 1240, left = 60, right = 30, top = 70;
  const double sx = (W - left - right) / (xmax - xmin);
  const double sy = sx * depth_scale;
  const double plot_h = dmax * sy + 20;
  Canvas cv(static_cast<int>(W), static_cast<int>(top + plot_h + 80));
  cairo_t* c = cv.c();
  auto X = [&](double x) { return left + (x - xmin) * sx; };
  // Depth below the skin (the skin drawn flat): the head's curvature would otherwise hide the
  // layers, which are what the picture is for.
  auto Y = [&](double x, double f) { return top + 10 + f * depth_mm(x) * sy; };
  const int n = 1200;
  for (int k = 0; k <= NL; ++k) {
    bool pen = false;
    for (int i = 0; i <= n; ++i) {
      const double x = xmin + (xmax - xmin) * i / n;
      if (!covered(x)) {
        pen = false;
        continue;
      }
      pen ? cairo_line_to(c, X(x), Y(x, F[k])) : cairo_move_to(c, X(x), Y(x, F[k]));
      pen = true;
    }
    cairo_set_source_rgb(c, k == 0 ? 0.1 : (k == NL ? 0.55 : 0.35), k == 0 ? 0.1 : 0.35,
                         k == 0 ? 0.1 : (k == NL ? 0.1 : 0.35));
    cairo_set_line_width(c, k == 0 ? 3.0 : (k == NL ? 2.5 : 1.0));
    cairo_stroke(c);
  }
  for (double x : walls) {
    cairo_move_to(c, X(x), Y(x, 0));
    cairo_line_to(c, X(x), Y(x, 1));
    cairo_set_source_rgb(c, 0.35, 0.35, 0.35);
    cairo_set_line_width(c, 1.0);
    cairo_stroke(c);
    for (int k = 0; k <= NL; ++k) {
      cairo_arc(c, X(x), Y(x, F[k]), 2.0, 0, 2 * std::numbers::pi);
      cairo_fill(c);
    }
  }
  cv.text(left, 28, title, 16);
  cv.text(left, 50,
          cat("section at z = ", std::round(s.z_c_mm * 10) / 10, " mm through the wound, skin drawn flat, depth below it x",
              depth_scale, "; ", NL, " layers, thickness ",
              o.constant_thickness_mm > 0 ? cat(o.constant_thickness_mm, " mm (constant)")
                                          : std::string("from the model"),
              "; bold: skin (top) and bone (bottom); dots: where the section meets element edges"),
          12);
  cv.text(left, top + plot_h + 40,
          cat("arc length (mm) from ", std::round(xmin), " to ", std::round(xmax),
              " at the reference radius ", std::round(s.ref_radius_mm), " mm"),
          12);
  cv.write(path);
}

}  // namespace caps::fem

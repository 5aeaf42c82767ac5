#include "caps/plan/plan_figure.hpp"

#include <cairo.h>

#include <algorithm>
#include <cmath>
#include <memory>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/volume/image_io.hpp"

namespace fs = std::filesystem;

namespace caps::plan {

namespace {

using V2 = Eigen::Vector2d;


void text(cairo_t* cr, double x, double y, const std::string& s, double size, double align = 0.0,
          double r = 0.1, double g = 0.1, double b = 0.1, bool halo = false) {
  cairo_set_font_size(cr, size);
  cairo_text_extents_t ext;
  cairo_text_extents(cr, s.c_str(), &ext);
  const double x0 = x - align * ext.x_advance;
  if (halo) {
    cairo_set_source_rgba(cr, 1, 1, 1, 0.8);
    cairo_rectangle(cr, x0 - 1.5, y + ext.y_bearing - 1.5, ext.width + 3, ext.height + 3);
    cairo_fill(cr);
  }
  cairo_move_to(cr, x0, y);
  cairo_set_source_rgb(cr, r, g, b);
  cairo_show_text(cr, s.c_str());
}

}  // namespace

void write_plan_png(const fs::path& path, const Plan& plan, const PatientModel& model,
                    const PlanFigureOptions& o) {
  const BorderLoop loop = border_loop(plan);
  const int n = loop.size();
  // Picture coordinates (mm): right = +theta, up = superior; local x = cos(phi) up + sin(phi) right.
  const double phi = deg_to_rad(plan.frame.orientation_deg);
  const V2 ex(std::sin(phi), std::cos(phi)), ey(-std::cos(phi), std::sin(phi));
  auto pic = [&](const V2& xy) -> V2 { return xy.x() * ex + xy.y() * ey; };
  auto local = [&](const V2& p) -> V2 { return {p.dot(ex), p.dot(ey)}; };
  V2 lo(1e30, 1e30), hi(-1e30, -1e30);
  for (const auto& xy : loop.local_mm) lo = lo.cwiseMin(pic(xy)), hi = hi.cwiseMax(pic(xy));
  lo.array() -= o.margin_mm;
  hi.array() += o.margin_mm;
  const double ppm = std::min(o.pixels_per_mm, o.max_size_px / std::max(hi.x() - lo.x(), hi.y() - lo.y()));
  const int W = static_cast<int>(std::ceil((hi.x() - lo.x()) * ppm));
  const int H = static_cast<int>(std::ceil((hi.y() - lo.y()) * ppm));
  const int left = 20, top = 40, right = std::max(20, 680 - W), bottom = 84 + 16 * static_cast<int>((plan.sutures.size() + 2) / 3);
  std::unique_ptr<cairo_surface_t, decltype(&cairo_surface_destroy)> surface(
      cairo_image_surface_create(CAIRO_FORMAT_RGB24, left + W + right, top + H + bottom),
      cairo_surface_destroy);
  std::unique_ptr<cairo_t, decltype(&cairo_destroy)> ctx(cairo_create(surface.get()), cairo_destroy);
  cairo_t* cr = ctx.get();
  cairo_set_source_rgb(cr, 1, 1, 1);
  cairo_paint(cr);
  cairo_select_font_face(cr, "DejaVu Sans", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);

  // The map under the plan, sampled per pixel through the frame.
  const bool colour = model.has_color() && !o.use_thickness;
  double vmax = 5;
  if (!colour)
    for (int y = 0; y < H; y += 8)
      for (int x = 0; x < W; x += 8) {
        const V2 tz = plan.frame.to_theta_z(local(V2(lo.x() + x / ppm, hi.y() - y / ppm)));
        vmax = std::max(vmax, model.thickness(tz[0], tz[1]));
      }
  vmax = std::ceil(vmax / 5) * 5;
  cairo_surface_flush(surface.get());
  unsigned char* data = cairo_image_surface_get_data(surface.get());
  const int stride = cairo_image_surface_get_stride(surface.get());
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const V2 tz = plan.frame.to_theta_z(local(V2(lo.x() + (x + 0.5) / ppm, hi.y() - (y + 0.5) / ppm)));
      Eigen::Vector3d c = colour ? model.color_at(tz[0], tz[1]) : viridis(model.thickness(tz[0], tz[1]) / vmax);
      if (!model.has_z(tz[1]) || model.flags_at(tz[0], tz[1]) != 0)
        c = ((x + y) / 4) % 2 ? Eigen::Vector3d(0.75, 0.75, 0.75) : Eigen::Vector3d(0.9, 0.9, 0.9);
      auto byte = [](double v) { return static_cast<std::uint32_t>(std::clamp(v, 0.0, 1.0) * 255 + 0.5); };
      *(reinterpret_cast<std::uint32_t*>(data + (top + y) * stride) + left + x) =
          (byte(c[0]) << 16) | (byte(c[1]) << 8) | byte(c[2]);
    }
  cairo_surface_mark_dirty(surface.get());
  auto px = [&](const V2& xy) -> V2 {
    const V2 p = pic(xy);
    return {left + (p.x() - lo.x()) * ppm, top + (hi.y() - p.y()) * ppm};
  };

  // The hole (excised tissue) and its border loop.
  cairo_set_line_join(cr, CAIRO_LINE_JOIN_ROUND);
  for (int i = 0; i < n; ++i) {
    const V2 p = px(loop.local_mm[i]);
    i == 0 ? cairo_move_to(cr, p.x(), p.y()) : cairo_line_to(cr, p.x(), p.y());
  }
  cairo_close_path(cr);
  cairo_set_source_rgba(cr, 0.85, 0.1, 0.1, 0.25);
  cairo_fill_preserve(cr);
  cairo_set_source_rgb(cr, 0.85, 0.1, 0.1);
  cairo_set_line_width(cr, 2.0);
  cairo_stroke(cr);
  // The surgeon's cutting paths, thin and dashed over the loop.
  const double dash[] = {5.0, 3.0};
  cairo_set_dash(cr, dash, 2, 0);
  cairo_set_line_width(cr, 1.2);
  cairo_set_source_rgb(cr, 0.05, 0.05, 0.05);
  for (const auto& path : plan.paths)
    for (std::size_t k = 0; k < path.size(); ++k) {
      const auto& s = plan.points[path[k]];
      const V2 p = px(plan.frame.to_local(s.theta_deg, s.z_mm));
      k == 0 ? cairo_move_to(cr, p.x(), p.y()) : cairo_line_to(cr, p.x(), p.y());
    }
  cairo_stroke(cr);
  cairo_set_dash(cr, nullptr, 0, 0);

  // Node numbers on the tissue side of each node (so twins are told apart).
  std::vector<V2> side(n);
  for (int i = 0; i < n; ++i) {
    const V2 a = px(loop.local_mm[(i + n - 1) % n]), b = px(loop.local_mm[i]), c = px(loop.local_mm[(i + 1) % n]);
    const V2 din = (b - a).normalized(), dout = (c - b).normalized();
    // Pixel y grows downwards, so "left" of a direction seen on screen is (d.y, -d.x).
    V2 s = V2(din.y(), -din.x()) + V2(dout.y(), -dout.x());
    if (s.norm() < 0.3) s = din;
    if (!s.allFinite() || s.norm() < 1e-9) s = V2(0, -1);
    side[i] = s.normalized();
  }
  for (int i = 0; i < n; ++i) {
    const V2 p = px(loop.local_mm[i]);
    cairo_arc(cr, p.x(), p.y(), 2.5, 0, 2 * kPi);
    cairo_set_source_rgb(cr, 0.85, 0.1, 0.1);
    cairo_fill(cr);
    const V2 t = p + 13.0 * side[i];
    text(cr, t.x(), t.y() + 4, std::to_string(i), 13, 0.5, 0.6, 0.0, 0.0, true);
  }
  // Sutures: dashed blue lines join the nodes that meet; each pair labelled at its two edges.
  const double dot[] = {2.0, 3.0};
  for (std::size_t k = 0; k < plan.sutures.size(); ++k) {
    const auto q = oriented_suture(plan.sutures[k], n);
    cairo_set_source_rgb(cr, 0.1, 0.25, 0.85);
    cairo_set_line_width(cr, 1.2);
    cairo_set_dash(cr, dot, 2, 0);
    for (auto [u, v] : {std::pair{q[0], q[2]}, std::pair{q[1], q[3]}}) {
      if (u == v) {  // a corner being closed
        const V2 p = px(loop.local_mm[u]);
        cairo_set_dash(cr, nullptr, 0, 0);
        cairo_arc(cr, p.x(), p.y(), 6, 0, 2 * kPi);
        cairo_stroke(cr);
        cairo_set_dash(cr, dot, 2, 0);
        continue;
      }
      const V2 a = px(loop.local_mm[u]), b = px(loop.local_mm[v]);
      cairo_move_to(cr, a.x(), a.y());
      cairo_line_to(cr, b.x(), b.y());
      cairo_stroke(cr);
    }
    cairo_set_dash(cr, nullptr, 0, 0);
    const auto edges = suture_edges(q, n);
    for (int e : {edges[0][edges[0].size() / 2], edges[1][edges[1].size() / 2]}) {
      const V2 a = px(loop.local_mm[e]), b = px(loop.local_mm[(e + 1) % n]);
      if ((b - a).norm() < 36) continue;  // too short to label legibly; the list below has it
      const V2 d = (b - a).normalized();
      const V2 m = 0.5 * (a + b) + 9.0 * V2(d.y(), -d.x());
      text(cr, m.x(), m.y() + 4, cat("s", k), 11, 0.5, 0.1, 0.25, 0.85, true);
    }
  }
  // Scale bar (10 mm), frame, title and legend.
  cairo_set_source_rgb(cr, 0.1, 0.1, 0.1);
  cairo_set_line_width(cr, 3);
  cairo_move_to(cr, left + 8, top + H - 10);
  cairo_line_to(cr, left + 8 + 10 * ppm, top + H - 10);
  cairo_stroke(cr);
  text(cr, left + 8 + 5 * ppm, top + H - 16, "10 mm", 11, 0.5, 0.1, 0.1, 0.1, true);
  cairo_set_line_width(cr, 1);
  cairo_rectangle(cr, left - 0.5, top - 0.5, W + 1, H + 1);
  cairo_stroke(cr);
  std::string params;
  for (const auto& [k, v] : plan.parameters) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%s%s %.4g", params.empty() ? "" : ", ", k.c_str(), v);
    params += buf;
  }
  char where[128];
  std::snprintf(where, sizeof where, "at theta %.1f deg, z %.1f mm, orientation %.0f deg",
                plan.frame.theta_deg, plan.frame.z_mm, plan.frame.orientation_deg);
  text(cr, left, 18, cat(plan.procedure, params.empty() ? "" : " (" + params + ")"), 14);
  text(cr, left, 34, cat(where, "; superior up, patient's left to the right; ",
                         colour ? "skin colour" : cat("thickness 0-", vmax, " mm (viridis)")), 11);
  const int ly = top + H + 18;
  text(cr, left, ly, "red: border loop, node numbers on their tissue side; black dashed: cutting path", 10.5);
  text(cr, left, ly + 14, "blue dashed: nodes brought together; blue circle: corner closed; sK: suture "
                          "pair K; grey hatching: invalid cells", 10.5);
  std::string line;
  int row = 0;
  for (std::size_t k = 0; k < plan.sutures.size(); ++k) {
    const auto& s = plan.sutures[k];
    line += cat("s", k, " = ", suture_text(s), "   ");
    if (k % 3 == 2 || k + 1 == plan.sutures.size()) {
      text(cr, left, ly + 32 + 16 * row++, line, 11, 0, 0.1, 0.25, 0.85);
      line.clear();
    }
  }
  cairo_surface_flush(surface.get());
  write_file_atomic(path, [&](const fs::path& tmp) {
    if (cairo_surface_write_to_png(surface.get(), tmp.c_str()) != CAIRO_STATUS_SUCCESS)
      throw IoError(cat(path.string(), ": cannot write the PNG"));
  });
}

}  // namespace caps::plan

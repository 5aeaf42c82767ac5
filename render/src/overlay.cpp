#include "caps/render/overlay.hpp"

#include <cairo.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>

#include "caps/core/error.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/volume/image_io.hpp"

namespace caps::render {
namespace {

// Cairo works on ARGB32 words; the image is packed RGB. These copy between the two.
using SurfacePtr = std::unique_ptr<cairo_surface_t, decltype(&cairo_surface_destroy)>;

SurfacePtr to_surface(const RgbImage& img) {
  SurfacePtr s(cairo_image_surface_create(CAIRO_FORMAT_RGB24, img.width, img.height),
               cairo_surface_destroy);
  cairo_surface_flush(s.get());
  unsigned char* data = cairo_image_surface_get_data(s.get());
  const int stride = cairo_image_surface_get_stride(s.get());
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const std::uint8_t* p = &img.rgb[(std::size_t(y) * img.width + x) * 3];
      reinterpret_cast<std::uint32_t*>(data + y * stride)[x] =
          (std::uint32_t(p[0]) << 16) | (std::uint32_t(p[1]) << 8) | p[2];
    }
  cairo_surface_mark_dirty(s.get());
  return s;
}

void from_surface(cairo_surface_t* s, RgbImage& img) {
  cairo_surface_flush(s);
  const unsigned char* data = cairo_image_surface_get_data(s);
  const int stride = cairo_image_surface_get_stride(s);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const std::uint32_t w = reinterpret_cast<const std::uint32_t*>(data + y * stride)[x];
      std::uint8_t* p = &img.rgb[(std::size_t(y) * img.width + x) * 3];
      p[0] = (w >> 16) & 0xff;
      p[1] = (w >> 8) & 0xff;
      p[2] = w & 0xff;
    }
}

double nice_step(double range) {
  const double raw = range / 5.0;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 2.5, 5.0, 10.0})
    if (m * mag >= raw) return m * mag;
  return 10 * mag;
}

}  // namespace

Eigen::MatrixX3d displacement_colors(const SkinSurfaces& skin, double max_mm, double& used_max_mm) {
  const Eigen::VectorXd d = (skin.post.V - skin.pre.V).rowwise().norm();
  used_max_mm = max_mm > 0 ? max_mm : std::max(d.maxCoeff(), 1e-6);
  Eigen::MatrixX3d c(d.size(), 3);
  for (Eigen::Index i = 0; i < d.size(); ++i) c.row(i) = viridis(d[i] / used_max_mm).transpose();
  return c;
}

void draw_color_bar(RgbImage& image, double max_value, const std::string& unit,
                    const std::string& title) {
  if (!(max_value > 0)) throw InvalidInput(cat("colour bar: the range ", max_value, " must be positive"));
  SurfacePtr s = to_surface(image);
  std::unique_ptr<cairo_t, decltype(&cairo_destroy)> cr(cairo_create(s.get()), cairo_destroy);
  const double h = 0.55 * image.height, w = std::max(12.0, 0.025 * image.width);
  const double x0 = image.width - w - 0.12 * image.width, y0 = 0.5 * (image.height - h);
  const double font = std::max(10.0, 0.018 * image.width);
  cairo_set_source_rgba(cr.get(), 1, 1, 1, 0.85);
  cairo_rectangle(cr.get(), x0 - 0.4 * w, y0 - 2.6 * font, 0.12 * image.width + 1.4 * w, h + 4 * font);
  cairo_fill(cr.get());
  for (int i = 0; i < static_cast<int>(h); ++i) {
    const Eigen::Vector3d c = viridis(1.0 - i / h);
    cairo_set_source_rgb(cr.get(), c[0], c[1], c[2]);
    cairo_rectangle(cr.get(), x0, y0 + i, w, 1.0);
    cairo_fill(cr.get());
  }
  cairo_select_font_face(cr.get(), "DejaVu Sans", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr.get(), font);
  cairo_set_source_rgb(cr.get(), 0.1, 0.1, 0.1);
  cairo_set_line_width(cr.get(), 1.0);
  const double step = nice_step(max_value);
  for (double v = 0; v <= max_value * (1 + 1e-9); v += step) {
    const double y = y0 + h - v / max_value * h;
    cairo_move_to(cr.get(), x0 + w, y);
    cairo_line_to(cr.get(), x0 + w + 4, y);
    cairo_stroke(cr.get());
    char label[32];
    std::snprintf(label, sizeof label, step < 1 ? "%.1f" : "%.0f", v);
    cairo_move_to(cr.get(), x0 + w + 6, y + 0.35 * font);
    cairo_show_text(cr.get(), (std::string(label) + " " + unit).c_str());
  }
  cairo_move_to(cr.get(), x0 - 0.3 * w, y0 - 1.0 * font);
  cairo_show_text(cr.get(), title.c_str());
  from_surface(s.get(), image);
}

Eigen::Vector2d project(const Camera& camera, const RenderOptions& o, const Eigen::Vector3d& p) {
  // The same orthographic frame as render_image().
  const Eigen::Vector3d fwd = camera.forward.normalized();
  const Eigen::Vector3d up = (camera.up - camera.up.dot(fwd) * fwd).normalized();
  const Eigen::Vector3d right = fwd.cross(up);
  const double px = camera.width_mm / o.width;
  const Eigen::Vector3d q = p - camera.centre;
  return {q.dot(right) / px + 0.5 * o.width, 0.5 * o.height - q.dot(up) / px};
}

void draw_polylines(RgbImage& image, const Camera& camera, const RenderOptions& o,
                    const std::vector<std::vector<Eigen::Vector3d>>& lines) {
  SurfacePtr s = to_surface(image);
  std::unique_ptr<cairo_t, decltype(&cairo_destroy)> cr(cairo_create(s.get()), cairo_destroy);
  const double dash[] = {6.0, 4.0};
  cairo_set_dash(cr.get(), dash, 2, 0);
  cairo_set_line_width(cr.get(), std::max(1.5, 0.003 * o.width));
  cairo_set_source_rgb(cr.get(), 0.15, 0.1, 0.45);
  for (const auto& line : lines) {
    for (std::size_t i = 0; i < line.size(); ++i) {
      const Eigen::Vector2d q = project(camera, o, line[i]);
      (i == 0 ? cairo_move_to : cairo_line_to)(cr.get(), q.x(), q.y());
    }
    cairo_stroke(cr.get());
  }
  from_surface(s.get(), image);
}

std::vector<std::vector<Eigen::Vector3d>> plan_lines(const plan::Plan& plan, const PatientModel& model) {
  constexpr int kSamples = 16;
  std::vector<std::vector<Eigen::Vector3d>> lines;
  for (const auto& path : plan.paths) {
    std::vector<Eigen::Vector3d> line;
    for (std::size_t i = 0; i + 1 < path.size(); ++i) {
      const auto& a = plan.points.at(path[i]);
      const auto& b = plan.points.at(path[i + 1]);
      const double dtheta = std::remainder(b.theta_deg - a.theta_deg, 360.0);
      for (int k = (i == 0 ? 0 : 1); k <= kSamples; ++k) {
        const double t = double(k) / kSamples;
        line.push_back(model.skin_point(a.theta_deg + t * dtheta, a.z_mm + t * (b.z_mm - a.z_mm)));
      }
    }
    lines.push_back(std::move(line));
  }
  return lines;
}

std::vector<std::filesystem::path> render_views_with_overlays(const PatientModel& model,
                                                              const SkinSurfaces& skin,
                                                              const std::vector<View>& views,
                                                              const RenderOptions& options,
                                                              const Overlays& overlays,
                                                              const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> written;
  const double aspect = double(options.width) / options.height;
  double max_mm = 0;
  const Eigen::MatrixX3d heat = overlays.displacement_map
                                    ? displacement_colors(skin, overlays.displacement_max_mm, max_mm)
                                    : Eigen::MatrixX3d();
  for (View v : views) {
    const Camera cam = standard_camera(v, model, skin, aspect);
    RgbImage pre = render_image(skin.pre, skin.color, cam, options);
    if (!overlays.plan_lines.empty()) draw_polylines(pre, cam, options, overlays.plan_lines);
    written.push_back(dir / cat("pre_", view_name(v), ".png"));
    write_png(written.back(), pre);
    written.push_back(dir / cat("post_", view_name(v), ".png"));
    write_png(written.back(), render_image(skin.post, skin.color, cam, options));
    if (overlays.displacement_map) {
      RgbImage map = render_image(skin.post, heat, cam, options);
      draw_color_bar(map, max_mm, "mm", "displacement");
      written.push_back(dir / cat("displacement_", view_name(v), ".png"));
      write_png(written.back(), map);
    }
  }
  return written;
}

}  // namespace caps::render

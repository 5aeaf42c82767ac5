#include "caps/surface/color_picture.hpp"

#include <cairo.h>

#include <algorithm>
#include <memory>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"

namespace caps {

void write_color_picture(const std::filesystem::path& path, const PatientModel& model,
                         const std::string& title, const std::string& credit) {
  if (!model.has_color())
    throw InvalidInput(cat(path.string(), ": the model has no colour (no color.png)"));
  const auto& g = model.grid();
  const RgbImage& c = model.color();
  const int s = std::max(1, 1024 / g.n_theta);
  const int left = 70, top = 45, map_w = g.n_theta * s, map_h = g.n_z * s;
  const int width = left + map_w + 40, height = top + map_h + 75;
  std::unique_ptr<cairo_surface_t, decltype(&cairo_surface_destroy)> surf(
      cairo_image_surface_create(CAIRO_FORMAT_RGB24, width, height), cairo_surface_destroy);
  std::unique_ptr<cairo_t, decltype(&cairo_destroy)> cr(cairo_create(surf.get()), cairo_destroy);
  cairo_set_source_rgb(cr.get(), 1, 1, 1);
  cairo_paint(cr.get());
  cairo_surface_flush(surf.get());
  unsigned char* data = cairo_image_surface_get_data(surf.get());
  const int stride = cairo_image_surface_get_stride(surf.get());
  for (int y = 0; y < map_h; ++y)
    for (int x = 0; x < map_w; ++x) {
      const std::size_t o = (std::size_t(y / s) * c.width + x / s) * 3;
      auto* px = reinterpret_cast<std::uint32_t*>(data + (top + y) * stride) + left + x;
      *px = (std::uint32_t(c.rgb[o]) << 16) | (std::uint32_t(c.rgb[o + 1]) << 8) | c.rgb[o + 2];
    }
  cairo_surface_mark_dirty(surf.get());
  cairo_t* k = cr.get();
  cairo_select_font_face(k, "DejaVu Sans", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_source_rgb(k, 0.1, 0.1, 0.1);
  auto text = [&](double x, double y, const std::string& t, double size, double align = 0) {
    cairo_set_font_size(k, size);
    cairo_text_extents_t e;
    cairo_text_extents(k, t.c_str(), &e);
    cairo_move_to(k, x - align * e.x_advance, y);
    cairo_show_text(k, t.c_str());
  };
  text(left, 28, title, 15);
  cairo_set_line_width(k, 1);
  cairo_rectangle(k, left - 0.5, top - 0.5, map_w + 1, map_h + 1);
  cairo_stroke(k);
  for (int deg = -180; deg <= 180; deg += 45) {
    const double x = left + (deg - g.theta0_deg) / 360.0 * map_w;
    cairo_move_to(k, x, top + map_h);
    cairo_line_to(k, x, top + map_h + 5);
    cairo_stroke(k);
    text(x, top + map_h + 18, std::to_string(deg), 11, 0.5);
  }
  const double z_last = g.z_mm(g.n_z - 1);
  const double step = (z_last - g.z0_mm) > 150 ? 50 : 25;
  for (double z = std::ceil(g.z0_mm / step) * step; z <= z_last; z += step) {
    const double y = top + map_h - (z - g.z0_mm) / (z_last - g.z0_mm) * map_h;
    cairo_move_to(k, left - 5, y);
    cairo_line_to(k, left, y);
    cairo_stroke(k);
    text(left - 8, y + 4, std::to_string(static_cast<int>(z)), 11, 1.0);
  }
  text(left + 0.5 * map_w, top + map_h + 36,
       "theta (deg):  0 = front (face),  +90 = patient's left,  -90 = patient's right;  z (mm) up",
       12, 0.5);
  if (!credit.empty()) text(left, top + map_h + 60, credit, 10);
  write_file_atomic(path, [&](const std::filesystem::path& tmp) {
    if (cairo_surface_write_to_png(surf.get(), tmp.c_str()) != CAIRO_STATUS_SUCCESS)
      throw IoError(cat(path.string(), ": cannot write PNG"));
  });
}

}  // namespace caps

#include "caps/image/canvas.hpp"

#include <cairo-pdf.h>
#include <cairo.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>

#include "caps/core/error.hpp"
#include "caps/image/image_io.hpp"

namespace caps {

struct Canvas::Impl {
  cairo_surface_t* surface = nullptr;  // owned
  cairo_t* cr = nullptr;               // owned
  int width = 0, height = 0;
  bool vector = false;    // a PDF page: no pixels
  bool finished = false;  // the PDF page was finished (pdf())
  bool scaled = false;    // scale() was called: draw_image() cannot copy pixels
  std::string pdf;        // the PDF surface's output so far

  static cairo_status_t append(void* closure, const unsigned char* data, unsigned int length) {
    static_cast<Impl*>(closure)->pdf.append(reinterpret_cast<const char*>(data), length);
    return CAIRO_STATUS_SUCCESS;
  }

  // A PDF page (the Impl must not move: cairo keeps `this` as the stream's closure).
  Impl(double w_pt, double h_pt)
      : width(static_cast<int>(std::ceil(w_pt))), height(static_cast<int>(std::ceil(h_pt))),
        vector(true) {
    if (!(w_pt > 0 && h_pt > 0 && std::isfinite(w_pt) && std::isfinite(h_pt)))
      throw InvalidInput(cat("canvas: a ", w_pt, " x ", h_pt, " pt page; both sizes must be positive"));
    surface = cairo_pdf_surface_create_for_stream(&Impl::append, this, w_pt, h_pt);
    cr = cairo_create(surface);
    if (cairo_status(cr) != CAIRO_STATUS_SUCCESS) {
      cairo_destroy(cr);
      cairo_surface_destroy(surface);
      throw Error(cat("canvas: cannot create a ", w_pt, " x ", h_pt, " pt PDF page"));
    }
    cairo_pdf_surface_set_metadata(surface, CAIRO_PDF_METADATA_CREATOR, "caps");
    cairo_select_font_face(cr, "DejaVu Sans", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  }

  Impl(int w, int h) : width(w), height(h) {
    if (w < 1 || h < 1)
      throw InvalidInput(cat("canvas: ", w, " x ", h, " pixels; both sizes must be positive"));
    surface = cairo_image_surface_create(CAIRO_FORMAT_RGB24, w, h);
    cr = cairo_create(surface);
    if (cairo_status(cr) != CAIRO_STATUS_SUCCESS) {
      cairo_destroy(cr);
      cairo_surface_destroy(surface);
      throw Error(cat("canvas: cannot create a ", w, " x ", h, " drawing surface (out of memory?)"));
    }
    cairo_select_font_face(cr, "DejaVu Sans", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  }
  ~Impl() {
    cairo_destroy(cr);
    cairo_surface_destroy(surface);
  }
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;

  void source(const Eigen::Vector3d& c, double opacity = 1.0) {
    if (opacity >= 1.0) cairo_set_source_rgb(cr, c[0], c[1], c[2]);
    else cairo_set_source_rgba(cr, c[0], c[1], c[2], opacity);
  }
  void path(const std::vector<Eigen::Vector2d>& points, bool closed) {
    cairo_new_path(cr);
    for (const auto& p : points) cairo_line_to(cr, p.x(), p.y());
    if (closed) cairo_close_path(cr);
  }
  void stroke(const Pen& pen) {
    source(pen.colour);
    cairo_set_line_width(cr, pen.width_px);
    cairo_set_dash(cr, pen.dash_px.data(), static_cast<int>(pen.dash_px.size()), 0);
    cairo_set_line_join(cr, pen.round_joins ? CAIRO_LINE_JOIN_ROUND : CAIRO_LINE_JOIN_MITER);
    cairo_stroke(cr);
  }
  // Runs f on the raw pixels (0x00RRGGBB words, `stride` bytes a row), keeping cairo in step.
  template <typename F>
  void pixels(F&& f) const {
    if (vector) throw Error("canvas: a PDF page has no pixels; use pdf()");
    cairo_surface_flush(surface);
    unsigned char* data = cairo_image_surface_get_data(surface);
    f(data, cairo_image_surface_get_stride(surface));
    cairo_surface_mark_dirty(surface);
  }
};

Canvas::Canvas(int width, int height, const Eigen::Vector3d& background)
    : impl_(std::make_unique<Impl>(width, height)) {
  impl_->source(background);
  cairo_paint(impl_->cr);
}

Canvas::Canvas(const RgbImage& image) : Canvas(image.width, image.height) {
  draw_image(image, 0, 0);
}

Canvas Canvas::pdf_page(double width_pt, double height_pt) {
  Canvas c(1, 1);
  c.impl_ = std::make_unique<Impl>(width_pt, height_pt);
  c.impl_->source({1, 1, 1});
  cairo_paint(c.impl_->cr);
  return c;
}

void Canvas::scale(double factor) {
  if (!(factor > 0 && std::isfinite(factor)))
    throw InvalidInput(cat("canvas: scale ", factor, " must be positive"));
  cairo_scale(impl_->cr, factor, factor);
  impl_->scaled = true;
}

std::string Canvas::pdf() {
  if (!impl_->vector) throw Error("canvas: pdf() of a raster canvas; use image() or write_png()");
  if (!impl_->finished) {
    cairo_show_page(impl_->cr);
    cairo_surface_finish(impl_->surface);
    impl_->finished = true;
  }
  if (cairo_surface_status(impl_->surface) != CAIRO_STATUS_SUCCESS)
    throw Error(cat("canvas: cairo could not write the PDF page: ",
                    cairo_status_to_string(cairo_surface_status(impl_->surface))));
  return impl_->pdf;
}

Canvas::~Canvas() = default;
Canvas::Canvas(Canvas&&) noexcept = default;
Canvas& Canvas::operator=(Canvas&&) noexcept = default;

int Canvas::width() const { return impl_->width; }
int Canvas::height() const { return impl_->height; }

void Canvas::line(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Pen& pen) {
  impl_->path({a, b}, false);
  impl_->stroke(pen);
}

void Canvas::polyline(const std::vector<Eigen::Vector2d>& points, const Pen& pen, bool closed) {
  if (points.size() < 2) return;
  impl_->path(points, closed);
  impl_->stroke(pen);
}

void Canvas::fill_polygon(const std::vector<Eigen::Vector2d>& points,
                          const Eigen::Vector3d& colour, double opacity) {
  if (points.size() < 3) return;
  impl_->path(points, true);
  impl_->source(colour, opacity);
  cairo_fill(impl_->cr);
}

void Canvas::fill_rect(double x, double y, double w, double h, const Eigen::Vector3d& colour,
                       double opacity) {
  cairo_new_path(impl_->cr);
  cairo_rectangle(impl_->cr, x, y, w, h);
  impl_->source(colour, opacity);
  cairo_fill(impl_->cr);
}

void Canvas::stroke_rect(double x, double y, double w, double h, const Pen& pen) {
  cairo_new_path(impl_->cr);
  cairo_rectangle(impl_->cr, x, y, w, h);
  impl_->stroke(pen);
}

void Canvas::fill_circle(const Eigen::Vector2d& c, double r, const Eigen::Vector3d& colour) {
  cairo_new_path(impl_->cr);
  cairo_arc(impl_->cr, c.x(), c.y(), r, 0, 2 * std::numbers::pi);
  impl_->source(colour);
  cairo_fill(impl_->cr);
}

void Canvas::stroke_circle(const Eigen::Vector2d& c, double r, const Pen& pen) {
  cairo_new_path(impl_->cr);
  cairo_arc(impl_->cr, c.x(), c.y(), r, 0, 2 * std::numbers::pi);
  impl_->stroke(pen);
}

double Canvas::text_width(const std::string& text, double size_px) const {
  cairo_set_font_size(impl_->cr, size_px);
  cairo_text_extents_t ext;
  cairo_text_extents(impl_->cr, text.c_str(), &ext);
  return ext.x_advance;
}

void Canvas::text(double x, double y, const std::string& s, const TextStyle& style) {
  cairo_t* cr = impl_->cr;
  cairo_save(cr);
  cairo_translate(cr, x, y);
  if (style.rotate_deg != 0) cairo_rotate(cr, style.rotate_deg * std::numbers::pi / 180);
  cairo_set_font_size(cr, style.size_px);
  cairo_text_extents_t ext;
  cairo_text_extents(cr, s.c_str(), &ext);
  const double x0 = -style.align * ext.x_advance;
  if (style.halo) {
    cairo_new_path(cr);
    cairo_rectangle(cr, x0 - 1.5, ext.y_bearing - 1.5, ext.width + 3, ext.height + 3);
    cairo_set_source_rgba(cr, 1, 1, 1, 0.8);
    cairo_fill(cr);
  }
  cairo_new_path(cr);
  cairo_move_to(cr, x0, 0);
  impl_->source(style.colour);
  cairo_show_text(cr, s.c_str());
  cairo_restore(cr);
}

void Canvas::draw_image(const RgbImage& image, int x0, int y0, int scale) {
  if (scale < 1) throw InvalidInput(cat("canvas: image scale ", scale, " must be at least 1"));
  if (impl_->vector || impl_->scaled) {
    draw_image_in(image, x0, y0, double(image.width) * scale, double(image.height) * scale);
    return;
  }
  const int W = impl_->width, H = impl_->height;
  impl_->pixels([&](unsigned char* data, int stride) {
    for (int y = 0; y < image.height * scale; ++y) {
      const int ty = y0 + y;
      if (ty < 0 || ty >= H) continue;
      auto* row = reinterpret_cast<std::uint32_t*>(data + std::size_t(ty) * stride);
      for (int x = 0; x < image.width * scale; ++x) {
        const int tx = x0 + x;
        if (tx < 0 || tx >= W) continue;
        const std::uint8_t* p = &image.rgb[(std::size_t(y / scale) * image.width + x / scale) * 3];
        row[tx] = (std::uint32_t(p[0]) << 16) | (std::uint32_t(p[1]) << 8) | p[2];
      }
    }
  });
}

void Canvas::draw_image_in(const RgbImage& image, double x, double y, double w, double h) {
  if (image.width < 1 || image.height < 1) return;
  cairo_surface_t* img = cairo_image_surface_create(CAIRO_FORMAT_RGB24, image.width, image.height);
  cairo_surface_flush(img);
  unsigned char* data = cairo_image_surface_get_data(img);
  const int stride = cairo_image_surface_get_stride(img);
  for (int r = 0; r < image.height; ++r) {
    auto* row = reinterpret_cast<std::uint32_t*>(data + std::size_t(r) * stride);
    for (int c = 0; c < image.width; ++c) {
      const std::uint8_t* p = &image.rgb[(std::size_t(r) * image.width + c) * 3];
      row[c] = (std::uint32_t(p[0]) << 16) | (std::uint32_t(p[1]) << 8) | p[2];
    }
  }
  cairo_surface_mark_dirty(img);
  cairo_t* cr = impl_->cr;
  cairo_save(cr);
  cairo_translate(cr, x, y);
  cairo_scale(cr, w / image.width, h / image.height);
  cairo_set_source_surface(cr, img, 0, 0);
  cairo_pattern_set_filter(cairo_get_source(cr), CAIRO_FILTER_BILINEAR);
  cairo_new_path(cr);
  cairo_rectangle(cr, 0, 0, image.width, image.height);
  cairo_fill(cr);
  cairo_restore(cr);
  cairo_surface_destroy(img);
}

void Canvas::colour_bar(double x, double y, double w, double h,
                        const std::function<Eigen::Vector3d(double)>& map) {
  const int rows = std::max(1, static_cast<int>(h));
  for (int i = 0; i < rows; ++i)
    fill_rect(x, y + i, w, 1.0, map(rows > 1 ? 1.0 - double(i) / (rows - 1) : 1.0));
}

void Canvas::push_clip(double x, double y, double w, double h) {
  cairo_save(impl_->cr);
  cairo_new_path(impl_->cr);
  cairo_rectangle(impl_->cr, x, y, w, h);
  cairo_clip(impl_->cr);
}

void Canvas::pop_clip() { cairo_restore(impl_->cr); }

RgbImage Canvas::image() const {
  RgbImage img;
  img.width = impl_->width;
  img.height = impl_->height;
  img.rgb.resize(std::size_t(img.width) * img.height * 3);
  impl_->pixels([&](unsigned char* data, int stride) {
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) {
        const std::uint32_t w = reinterpret_cast<const std::uint32_t*>(data + std::size_t(y) * stride)[x];
        std::uint8_t* p = &img.rgb[(std::size_t(y) * img.width + x) * 3];
        p[0] = (w >> 16) & 0xff;
        p[1] = (w >> 8) & 0xff;
        p[2] = w & 0xff;
      }
  });
  return img;
}

void Canvas::write_png(const std::filesystem::path& path) const { caps::write_png(path, image()); }

}  // namespace caps

#include "caps/render/overlay.hpp"

#include <cairo.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "caps/core/error.hpp"
#include "caps/render/skin_surface.hpp"
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

// Decimals that print every multiple of `step` exactly (2.5 -> 1, 0.25 -> 2, 20 -> 0).
int decimals_of(double step) {
  for (int d = 0; d < 6; ++d) {
    const double scaled = step * std::pow(10.0, d);
    if (std::abs(scaled - std::round(scaled)) < 1e-6 * std::max(1.0, scaled)) return d;
  }
  return 6;
}

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> out;
  if (text.empty()) return out;
  std::size_t start = 0;
  for (std::size_t nl; (nl = text.find('\n', start)) != std::string::npos; start = nl + 1)
    out.push_back(text.substr(start, nl - start));
  out.push_back(text.substr(start));
  return out;
}

}  // namespace

double scale_top(const Eigen::VectorXd& value, double max_value) {
  if (max_value > 0) return max_value;
  const double largest = value.size() ? value.maxCoeff() : 0.0;
  return largest > 0 ? largest : 1.0;
}

Eigen::MatrixX3d scalar_colors(const Eigen::VectorXd& value, double max_value) {
  if (!(max_value > 0) || !std::isfinite(max_value))
    throw InvalidInput(cat("colour map: the top of the scale ", max_value, " must be positive"));
  Eigen::MatrixX3d c(value.size(), 3);
  // viridis() clamps to [0, 1]: compression (< 0) takes the first colour, beyond the top the last.
  for (Eigen::Index i = 0; i < value.size(); ++i) c.row(i) = viridis(value[i] / max_value).transpose();
  return c;
}

Eigen::VectorXd displacement_magnitude_mm(const SkinSurfaces& skin) {
  return (skin.post.V - skin.pre.V).rowwise().norm();
}

ScalarMap displacement_map(const SkinSurfaces& skin, double max_mm) {
  ScalarMap m;
  m.name = "displacement";
  m.value = displacement_magnitude_mm(skin);
  m.max_value = scale_top(m.value, max_mm);
  m.unit = "mm";
  m.title = "displacement";
  return m;
}

ScalarMap tension_map(const SkinSurfaces& skin, const fem::Mesh& mesh,
                      const Eigen::VectorXd& max_principal_mpa, double max_kpa) {
  if (max_kpa < 0 || !std::isfinite(max_kpa))
    throw InvalidInput(cat("tension map: the top of the scale ", max_kpa,
                           " kPa must be positive (or 0 for the 99th percentile)"));
  ScalarMap m;
  m.name = "tension";
  m.value = 1e3 * nodal_field_on_skin(skin, mesh, max_principal_mpa, 0.0);  // MPa -> kPa
  m.unit = "kPa";
  m.title = "max principal stress\n(skin tension), kPa";
  m.note = "\u2264 0 = compression";
  if (max_kpa > 0) {
    m.max_value = max_kpa;
    return m;
  }
  // By default the top of the scale is the 99th percentile over the skin faces: the largest
  // values sit at the sutured corners, where linear elasticity is singular (they grow as the
  // mesh is refined) and would leave the rest of the map in the bottom colour.
  std::vector<double> v(m.value.data(), m.value.data() + skin.n_micropolygon_vertices);
  double peak = 0, top = 0;
  if (!v.empty()) {
    peak = *std::max_element(v.begin(), v.end());
    auto k = v.begin() + static_cast<std::ptrdiff_t>(0.99 * static_cast<double>(v.size() - 1));
    std::nth_element(v.begin(), k, v.end());
    top = *k;
  }
  m.max_value = top > 0 ? top : scale_top(m.value, 0);
  if (peak > m.max_value) m.note += cat("\nscale: 99th percentile;\npeak ", std::lround(peak), " kPa");
  return m;
}

void draw_color_bar(RgbImage& image, double max_value, const std::string& unit,
                    const std::string& title, const std::string& note) {
  if (!(max_value > 0) || !std::isfinite(max_value))
    throw InvalidInput(cat("colour bar: the range ", max_value, " must be positive"));
  SurfacePtr s = to_surface(image);
  std::unique_ptr<cairo_t, decltype(&cairo_destroy)> cr(cairo_create(s.get()), cairo_destroy);
  const double h = 0.55 * image.height, w = std::max(12.0, 0.025 * image.width);
  const double x0 = image.width - w - 0.12 * image.width, y0 = 0.5 * (image.height - h);
  const double font = std::max(10.0, 0.018 * image.width), line = 1.25 * font;
  cairo_select_font_face(cr.get(), "DejaVu Sans", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr.get(), font);
  // Text lines start at the bar's left; a line too wide for the image is moved left so that it
  // stays whole, and the panel grows to cover it.
  const std::vector<std::string> title_lines = lines_of(title), note_lines = lines_of(note);
  auto text_x = [&](const std::string& text) {
    cairo_text_extents_t ext;
    cairo_text_extents(cr.get(), text.c_str(), &ext);
    return std::min(x0 - 0.3 * w, image.width - 4.0 - ext.x_advance);
  };
  double left = x0 - 0.4 * w;
  for (const auto& t : title_lines) left = std::min(left, text_x(t) - 0.3 * w);
  for (const auto& t : note_lines) left = std::min(left, text_x(t) - 0.3 * w);
  left = std::max(0.0, left);
  const double n_title = std::max<double>(1, title_lines.size());
  const double top = y0 - 2.6 * font - (n_title - 1) * line;
  const double bottom = y0 + h + 1.4 * font + note_lines.size() * line;
  cairo_set_source_rgba(cr.get(), 1, 1, 1, 0.85);
  cairo_rectangle(cr.get(), left, top, image.width - left, bottom - top);
  cairo_fill(cr.get());
  for (int i = 0; i < static_cast<int>(h); ++i) {
    const Eigen::Vector3d c = viridis(1.0 - i / h);
    cairo_set_source_rgb(cr.get(), c[0], c[1], c[2]);
    cairo_rectangle(cr.get(), x0, y0 + i, w, 1.0);
    cairo_fill(cr.get());
  }
  cairo_set_source_rgb(cr.get(), 0.1, 0.1, 0.1);
  cairo_set_line_width(cr.get(), 1.0);
  const double step = nice_step(max_value);
  const int decimals = decimals_of(step);
  auto tick = [&](double v, int decimals) {
    const double y = y0 + h - v / max_value * h;
    cairo_move_to(cr.get(), x0 + w, y);
    cairo_line_to(cr.get(), x0 + w + 4, y);
    cairo_stroke(cr.get());
    char label[48];
    std::snprintf(label, sizeof label, "%.*f", decimals, v);
    cairo_move_to(cr.get(), x0 + w + 6, y + 0.35 * font);
    cairo_show_text(cr.get(), (std::string(label) + " " + unit).c_str());
  };
  int k = 0;
  for (; k * step <= max_value * (1 + 1e-9); ++k) tick(k * step, decimals);
  // The top of the scale gets its own label (three significant digits) unless a tick is close to
  // it, so that the largest value can be read off the bar.
  if (max_value - (k - 1) * step > 0.3 * step)
    tick(max_value, std::max(decimals, 2 - static_cast<int>(std::floor(std::log10(max_value)))));
  for (std::size_t i = 0; i < title_lines.size(); ++i) {
    cairo_move_to(cr.get(), text_x(title_lines[i]),
                  y0 - 1.0 * font - double(title_lines.size() - 1 - i) * line);
    cairo_show_text(cr.get(), title_lines[i].c_str());
  }
  for (std::size_t i = 0; i < note_lines.size(); ++i) {
    cairo_move_to(cr.get(), text_x(note_lines[i]), y0 + h + 1.5 * font + double(i) * line);
    cairo_show_text(cr.get(), note_lines[i].c_str());
  }
  from_surface(s.get(), image);
}

void draw_polylines(RgbImage& image, const Camera& camera,
                    const std::vector<std::vector<Eigen::Vector3d>>& lines) {
  if (image.width != camera.width_px || image.height != camera.height_px)
    throw InvalidInput(cat("draw_polylines: the image is ", image.width, "x", image.height,
                           " pixels, the camera ", camera.width_px, "x", camera.height_px));
  SurfacePtr s = to_surface(image);
  std::unique_ptr<cairo_t, decltype(&cairo_destroy)> cr(cairo_create(s.get()), cairo_destroy);
  const double dash[] = {6.0, 4.0};
  cairo_set_dash(cr.get(), dash, 2, 0);
  cairo_set_line_width(cr.get(), std::max(1.5, 0.003 * camera.width_px));
  cairo_set_source_rgb(cr.get(), 0.15, 0.1, 0.45);
  for (const auto& line : lines) {
    for (std::size_t i = 0; i < line.size(); ++i) {
      const Eigen::Vector2d q = camera.project(line[i]);
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
  std::vector<Eigen::MatrixX3d> colors;
  for (const ScalarMap& m : overlays.scalar_maps) {
    if (m.value.size() != skin.post.V.rows())
      throw InvalidInput(cat("render: the ", m.name, " map has ", m.value.size(),
                             " values but the skin has ", skin.post.V.rows(), " vertices"));
    colors.push_back(scalar_colors(m.value, m.max_value));
  }
  for (View v : views) {
    const Camera cam = standard_camera(v, model, skin, options.width, options.height);
    RgbImage pre = render_image(skin.pre, skin.color, cam, options);
    if (!overlays.plan_lines.empty()) draw_polylines(pre, cam, overlays.plan_lines);
    written.push_back(dir / cat("pre_", view_name(v), ".png"));
    write_png(written.back(), pre);
    written.push_back(dir / cat("post_", view_name(v), ".png"));
    write_png(written.back(), render_image(skin.post, skin.color, cam, options));
    for (std::size_t i = 0; i < overlays.scalar_maps.size(); ++i) {
      const ScalarMap& m = overlays.scalar_maps[i];
      RgbImage map = render_image(skin.post, colors[i], cam, options);
      draw_color_bar(map, m.max_value, m.unit, m.title, m.note);
      written.push_back(dir / cat(m.name, "_", view_name(v), ".png"));
      write_png(written.back(), map);
    }
  }
  return written;
}

}  // namespace caps::render

#include "caps/render/overlay.hpp"

#include <algorithm>
#include <cmath>
#include <functional>
#include <cstdio>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "caps/core/error.hpp"
#include "caps/image/canvas.hpp"
#include "caps/image/colormap.hpp"
#include "caps/image/image_io.hpp"
#include "caps/render/skin_surface.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps::render {
namespace {

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

namespace {

// A vertical colour bar from lo (bottom) to hi (top) in colours map((v - lo) / (hi - lo)), ticks
// at the multiples of a round step labelled in `unit` (with a '+' on positive ones if
// `plus_sign`), and the ends labelled when no tick is close to them.
void draw_bar(RgbImage& image, double lo, double hi, const std::function<Eigen::Vector3d(double)>& map,
              const std::string& unit, const std::string& title, const std::string& note, bool plus_sign) {
  Canvas canvas(image);
  const double h = 0.55 * image.height, w = std::max(12.0, 0.025 * image.width);
  const double x0 = image.width - w - 0.12 * image.width, y0 = 0.5 * (image.height - h);
  const double font = std::max(10.0, 0.018 * image.width), line = 1.25 * font;
  const TextStyle style{.size_px = font};
  // Text lines start at the bar's left; a line too wide for the image is moved left so that it
  // stays whole, and the panel grows to cover it.
  const std::vector<std::string> title_lines = lines_of(title), note_lines = lines_of(note);
  auto text_x = [&](const std::string& text) {
    return std::min(x0 - 0.3 * w, image.width - 4.0 - canvas.text_width(text, font));
  };
  double left = x0 - 0.4 * w;
  for (const auto& t : title_lines) left = std::min(left, text_x(t) - 0.3 * w);
  for (const auto& t : note_lines) left = std::min(left, text_x(t) - 0.3 * w);
  left = std::max(0.0, left);
  const double n_title = std::max<double>(1, title_lines.size());
  const double top = y0 - 2.6 * font - (n_title - 1) * line;
  const double bottom = y0 + h + 1.4 * font + note_lines.size() * line;
  canvas.fill_rect(left, top, image.width - left, bottom - top, {1, 1, 1}, 0.85);
  canvas.colour_bar(x0, y0, w, h, map);
  const double range = hi - lo;
  const double step = nice_step(hi > 0 && lo < 0 ? std::max(hi, -lo) : range);
  const int decimals = decimals_of(step);
  auto tick = [&](double v, int decimals) {
    const double y = y0 + h - (v - lo) / range * h;
    canvas.line(Eigen::Vector2d(x0 + w, y), Eigen::Vector2d(x0 + w + 4, y));
    char label[48];
    std::snprintf(label, sizeof label, "%s%.*f", plus_sign && v > 0 ? "+" : "", decimals, v);
    canvas.text(x0 + w + 6, y + 0.35 * font, std::string(label) + " " + unit, style);
  };
  const int k0 = static_cast<int>(std::ceil(lo / step - 1e-9)), k1 = static_cast<int>(std::floor(hi / step + 1e-9));
  for (int k = k0; k <= k1; ++k) tick(k * step, decimals);
  // The ends of the scale get their own labels (three significant digits) unless a tick is close
  // to them, so that the extreme values can be read off the bar.
  auto end_decimals = [&](double v) {
    return std::max(decimals, 2 - static_cast<int>(std::floor(std::log10(std::abs(v)))));
  };
  if (hi - k1 * step > 0.3 * step) tick(hi, end_decimals(hi));
  if (lo < 0 && k0 * step - lo > 0.3 * step) tick(lo, end_decimals(lo));
  for (std::size_t i = 0; i < title_lines.size(); ++i)
    canvas.text(text_x(title_lines[i]), y0 - 1.0 * font - double(title_lines.size() - 1 - i) * line,
                title_lines[i], style);
  for (std::size_t i = 0; i < note_lines.size(); ++i)
    canvas.text(text_x(note_lines[i]), y0 + h + 1.5 * font + double(i) * line, note_lines[i], style);
  image = canvas.image();
}

}  // namespace

void draw_color_bar(RgbImage& image, double max_value, const std::string& unit,
                    const std::string& title, const std::string& note) {
  if (!(max_value > 0) || !std::isfinite(max_value))
    throw InvalidInput(cat("colour bar: the range ", max_value, " must be positive"));
  draw_bar(image, 0.0, max_value, viridis, unit, title, note, false);
}

Eigen::MatrixX3d signed_colors(const Eigen::VectorXd& value, double max_value) {
  if (!(max_value > 0) || !std::isfinite(max_value))
    throw InvalidInput(cat("signed colours: the range ", max_value, " must be positive"));
  Eigen::MatrixX3d c(value.size(), 3);
  for (Eigen::Index i = 0; i < value.size(); ++i) c.row(i) = signed_colour(value[i] / max_value).transpose();
  return c;
}

Eigen::Vector3d signed_colour(double t) {
  const Eigen::Vector3d blue(0.13, 0.35, 0.75), white(0.97, 0.97, 0.97), red(0.78, 0.12, 0.12);
  t = std::clamp(t, -1.0, 1.0);
  return t < 0 ? Eigen::Vector3d(white + (-t) * (blue - white)) : Eigen::Vector3d(white + t * (red - white));
}

void draw_signed_color_bar(RgbImage& image, double max_value, const std::string& unit,
                           const std::string& title, const std::string& note) {
  if (!(max_value > 0) || !std::isfinite(max_value))
    throw InvalidInput(cat("colour bar: the range ", max_value, " must be positive"));
  draw_bar(image, -max_value, max_value, [](double t) { return signed_colour(2 * t - 1); }, unit, title,
           note, true);
}

namespace {

// The width of a scalar map's margin for its colour bar, in units of the view's width.
constexpr double kLegendMargin = 0.3;

// `image` with `margin` columns of `colour` added on its right.
RgbImage with_right_margin(const RgbImage& image, int margin, const Eigen::Vector3d& colour) {
  RgbImage out;
  out.width = image.width + margin;
  out.height = image.height;
  out.rgb.resize(static_cast<std::size_t>(out.width) * out.height * 3);
  for (int y = 0; y < out.height; ++y) {
    std::copy_n(image.rgb.begin() + static_cast<std::ptrdiff_t>(y) * image.width * 3,
                image.width * 3, out.rgb.begin() + static_cast<std::ptrdiff_t>(y) * out.width * 3);
    for (int x = image.width; x < out.width; ++x) out.set(x, y, colour);
  }
  return out;
}

// Polylines in LPS mm drawn with `pen` at their pixels camera.project(p); with `hits`, only the
// runs of points not hidden by the surface (no deeper than the surface met through their pixel,
// plus kLineDepthToleranceMm).
constexpr double kLineDepthToleranceMm = 1.0;

void draw_projected(RgbImage& image, const Camera& camera,
                    const std::vector<std::vector<Eigen::Vector3d>>& lines, const Pen& pen,
                    const PixelHits* hits, const char* who) {
  if (image.width != camera.width_px || image.height != camera.height_px)
    throw InvalidInput(cat(who, ": the image is ", image.width, "x", image.height,
                           " pixels, the camera ", camera.width_px, "x", camera.height_px));
  if (hits && (hits->width != camera.width_px || hits->height != camera.height_px))
    throw InvalidInput(cat(who, ": the hits are ", hits->width, "x", hits->height,
                           " pixels, the camera ", camera.width_px, "x", camera.height_px));
  auto visible = [&](const Eigen::Vector3d& p, const Eigen::Vector2d& q) {
    if (!hits) return true;
    const int x = static_cast<int>(std::floor(q.x())), y = static_cast<int>(std::floor(q.y()));
    if (x < 0 || y < 0 || x >= hits->width || y >= hits->height) return true;
    return camera.depth_mm(p) <=
           hits->depth_mm[static_cast<std::size_t>(y) * hits->width + x] + kLineDepthToleranceMm;
  };
  Canvas canvas(image);
  for (const auto& line : lines) {
    std::vector<Eigen::Vector2d> run;
    for (const auto& p : line) {
      const Eigen::Vector2d q = camera.project(p);
      if (visible(p, q)) {
        run.push_back(q);
        continue;
      }
      if (run.size() >= 2) canvas.polyline(run, pen);
      run.clear();
    }
    if (run.size() >= 2) canvas.polyline(run, pen);
  }
  image = canvas.image();
}

}  // namespace

void draw_polylines(RgbImage& image, const Camera& camera,
                    const std::vector<std::vector<Eigen::Vector3d>>& lines,
                    const PixelHits* hits) {
  draw_projected(image, camera, lines,
                 Pen{.colour = {0.15, 0.1, 0.45},
                     .width_px = std::max(1.5, 0.003 * camera.width_px),
                     .dash_px = {6.0, 4.0}},
                 hits, "draw_polylines");
}

void draw_suture_lines(RgbImage& image, const Camera& camera,
                       const std::vector<std::vector<Eigen::Vector3d>>& lines,
                       const PixelHits* hits) {
  draw_projected(image, camera, lines,
                 Pen{.colour = {0.55, 0.08, 0.1},
                     .width_px = std::max(1.2, 0.0025 * camera.width_px),
                     .round_joins = true},
                 hits, "draw_suture_lines");
}

std::vector<std::vector<int>> suture_loops(const SkinSurfaces& skin) {
  // directed edges of the micropolygons without their opposite: the rim and the lips
  std::set<std::pair<int, int>> directed;
  for (Eigen::Index f = 0; f < skin.pre.F.rows(); ++f) {
    if (skin.face_part[static_cast<std::size_t>(f)] != SkinPart::Micropolygon) continue;
    for (int k = 0; k < 3; ++k) directed.insert({skin.pre.F(f, k), skin.pre.F(f, (k + 1) % 3)});
  }
  std::map<int, int> next;
  for (const auto& [a, b] : directed)
    if (!directed.count({b, a})) next[a] = b;
  std::vector<std::vector<int>> loops;
  while (!next.empty()) {
    std::vector<int> loop;
    for (int v = next.begin()->first; next.count(v);) {
      loop.push_back(v);
      const int w = next[v];
      next.erase(v);
      v = w;
    }
    if (loop.size() >= 2) loops.push_back(std::move(loop));
  }
  // the outer rim: the loop of largest counter-clockwise area in (theta, z)
  std::size_t rim = loops.size();
  double rim_area = 0;
  for (std::size_t l = 0; l < loops.size(); ++l) {
    double a = 0;
    for (std::size_t i = 0; i < loops[l].size(); ++i) {
      const Eigen::Vector2d p = skin.theta_z.row(loops[l][i]);
      const Eigen::Vector2d q = skin.theta_z.row(loops[l][(i + 1) % loops[l].size()]);
      a += p.x() * q.y() - q.x() * p.y();
    }
    if (a > rim_area) {
      rim_area = a;
      rim = l;
    }
  }
  if (rim < loops.size()) loops.erase(loops.begin() + static_cast<std::ptrdiff_t>(rim));
  return loops;
}

std::vector<std::vector<Eigen::Vector3d>> suture_lines(const SkinSurfaces& skin) {
  std::vector<std::vector<Eigen::Vector3d>> out;
  for (const std::vector<int>& loop : suture_loops(skin)) {
    std::vector<Eigen::Vector3d> line;
    for (int v : loop) line.push_back(skin.post.V.row(v).transpose());
    line.push_back(line.front());
    out.push_back(std::move(line));
  }
  return out;
}

double scale_bar_length_mm(double width_mm) {
  if (!(width_mm > 0) || !std::isfinite(width_mm))
    throw InvalidInput(cat("scale bar: the image width ", width_mm, " mm must be positive"));
  const double limit = width_mm / 5.0;
  double mag = std::pow(10.0, std::floor(std::log10(limit)));
  double best = mag;
  for (double m : {1.0, 2.0, 5.0})
    if (m * mag <= limit * (1 + 1e-12)) best = m * mag;
  return best;
}

void draw_scale_bar(RgbImage& image, const Camera& camera) {
  if (camera.projection != Projection::Orthographic)
    throw InvalidInput("scale bar: a perspective image has no single scale; use an orthographic camera");
  if (image.width != camera.width_px || image.height != camera.height_px)
    throw InvalidInput(cat("draw_scale_bar: the image is ", image.width, "x", image.height,
                           " pixels, the camera ", camera.width_px, "x", camera.height_px));
  const double mm = scale_bar_length_mm(camera.width_mm);
  const double px = mm * camera.width_px / camera.width_mm;
  Canvas canvas(image);
  const double font = std::max(10.0, 0.018 * image.width);
  const double margin = std::max(6.0, 0.02 * image.width);
  const double x0 = margin + 0.5 * font, y = image.height - margin - 0.6 * font;
  char label[32];
  std::snprintf(label, sizeof label, "%g mm", mm);
  const double panel_w = std::max(px, canvas.text_width(label, font)) + font;
  canvas.fill_rect(margin, y - 2.2 * font, panel_w, 2.8 * font, {1, 1, 1}, 0.85);
  const Pen bar{.colour = {0, 0, 0}, .width_px = std::max(2.0, 0.004 * image.width)};
  const Pen tick{.colour = {0, 0, 0}, .width_px = std::max(1.0, 0.002 * image.width)};
  canvas.line({x0, y}, {x0 + px, y}, bar);
  canvas.line({x0, y - 0.4 * font}, {x0, y + 0.3 * font}, tick);
  canvas.line({x0 + px, y - 0.4 * font}, {x0 + px, y + 0.3 * font}, tick);
  canvas.text(x0, y - 0.7 * font, label, TextStyle{.size_px = font});
  image = canvas.image();
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
                                                              const std::filesystem::path& dir,
                                                              Reporter* reporter) {
  std::vector<std::filesystem::path> written;
  Progress progress(reporter, "rendering the views", static_cast<double>(views.size()));
  std::vector<Eigen::MatrixX3d> colors;
  for (const ScalarMap& m : overlays.scalar_maps) {
    if (m.value.size() != skin.post.V.rows())
      throw InvalidInput(cat("render: the ", m.name, " map has ", m.value.size(),
                             " values but the skin has ", skin.post.V.rows(), " vertices"));
    colors.push_back(scalar_colors(m.value, m.max_value));
  }
  const std::vector<std::vector<Eigen::Vector3d>> sutures =
      overlays.suture_lines ? suture_lines(skin) : std::vector<std::vector<Eigen::Vector3d>>{};
  for (View v : views) {
    progress.update(static_cast<double>(written.size()) / (2 + overlays.scalar_maps.size()));
    const Camera cam = standard_camera(v, model, skin, options.width, options.height);
    const bool bar = overlays.scale_bar && cam.projection == Projection::Orthographic;
    RgbImage pre = render_skin(skin, 0.0, skin.color, cam, options);
    if (!overlays.plan_lines.empty()) {
      const PixelHits hits = pixel_hits(skin.pre, cam);
      draw_polylines(pre, cam, overlays.plan_lines, &hits);
    }
    if (bar) draw_scale_bar(pre, cam);
    written.push_back(dir / cat("pre_", view_name(v), ".png"));
    write_png(written.back(), pre);
    RgbImage post = render_skin(skin, 1.0, skin.color, cam, options);
    if (!sutures.empty()) {
      const PixelHits hits = pixel_hits(skin.post, cam);
      draw_suture_lines(post, cam, sutures, &hits);
    }
    if (bar) draw_scale_bar(post, cam);
    written.push_back(dir / cat("post_", view_name(v), ".png"));
    write_png(written.back(), post);
    for (std::size_t i = 0; i < overlays.scalar_maps.size(); ++i) {
      const ScalarMap& m = overlays.scalar_maps[i];
      // The colour bar's panel in a margin to the right of the view, not over the face (it
      // covered the cheek's side of a front view): the view itself as in pre_ and post_.
      RgbImage view = render_skin(skin, 1.0, colors[i], cam, options);
      if (bar) draw_scale_bar(view, cam);
      RgbImage map = with_right_margin(
          view, static_cast<int>(std::lround(kLegendMargin * options.width)), options.background);
      draw_color_bar(map, m.max_value, m.unit, m.title, m.note);
      written.push_back(dir / cat(m.name, "_", view_name(v), ".png"));
      write_png(written.back(), map);
    }
  }
  return written;
}

}  // namespace caps::render

#include "caps/volume/model_figures.hpp"

#include <algorithm>
#include <cmath>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/image/canvas.hpp"
#include "caps/image/colormap.hpp"

namespace fs = std::filesystem;

namespace caps {
namespace {

using V2 = Eigen::Vector2d;

// A figure of one map over the grid: the map at `scale` pixels per cell inside margins, with
// theta ticks along the bottom, z ticks along the left, a frame, axis titles and a title.
struct MapFigure {
  static constexpr int kLeft = 70, kTop = 46, kRight = 150, kBottom = 64;
  const CylinderGrid& g;  // not owned; outlives the figure
  int scale, map_w, map_h;
  Canvas canvas;

  // Pixels per cell so the map is about 1000 pixels wide.
  explicit MapFigure(const CylinderGrid& grid)
      : g(grid),
        scale(std::max(1, 1024 / grid.n_theta)),
        map_w(grid.n_theta * scale),
        map_h(grid.n_z * scale),
        canvas(kLeft + map_w + kRight, kTop + map_h + kBottom) {}

  void text(double x, double y, const std::string& s, double size, double align = 0.0,
            double rotate_deg = 0.0) {
    canvas.text(x, y, s, {.size_px = size, .align = align, .rotate_deg = rotate_deg});
  }
  void tick(double x0, double y0, double x1, double y1) { canvas.line(V2(x0, y0), V2(x1, y1)); }

  void axes_and_title(const std::string& title) {
    const double x0 = kLeft, y0 = kTop, x1 = kLeft + map_w, y1 = kTop + map_h;
    canvas.stroke_rect(x0 - 0.5, y0 - 0.5, map_w + 1, map_h + 1);
    for (int deg = -180; deg <= 180; deg += 45) {
      const double x = x0 + (deg - g.theta0_deg) / g.dtheta_deg() * scale;
      tick(x, y1, x, y1 + 5);
      text(x, y1 + 18, std::to_string(deg), 11, 0.5);
    }
    text(0.5 * (x0 + x1), y1 + 36, "theta (deg):  0 = front (face),  +90 = patient's left,  "
                                   "-90 = patient's right", 12, 0.5);
    const double z_top = g.z_mm(g.n_z - 1);
    const double step = (z_top - g.z0_mm) > 150 ? 50.0 : 20.0;
    for (double z = std::ceil(g.z0_mm / step) * step; z <= z_top; z += step) {
      const double y = y1 - (z - g.z0_mm) / g.dz_mm * scale;
      tick(x0 - 5, y, x0, y);
      text(x0 - 8, y + 4, cat(static_cast<int>(z)), 11, 1.0);
    }
    text(16, 0.5 * (y0 + y1), "z (mm, superior up)", 12, 0.5, -90);
    text(kLeft, 28, title, 15);
  }
};

// The grey hatching of cells without a valid measurement, at pixel (x, y).
Eigen::Vector3d hatch(int x, int y) {
  return ((x + y) / 3) % 2 ? Eigen::Vector3d(0.78, 0.78, 0.78) : Eigen::Vector3d(0.88, 0.88, 0.88);
}

// A map of thicknesses (mm) with a colour bar; cells where `invalid` is non-zero are hatched and
// explained by `legend`.
void write_mm_map_png(const fs::path& path, const CylindricalMaps& maps,
                      const std::vector<float>& values, const std::vector<std::uint8_t>& invalid,
                      const std::string& bar_label, const std::string& legend,
                      const std::string& title, const std::string& credit) {
  const auto& g = maps.grid;
  MapFigure fig(g);
  const int s = fig.scale;
  // Colour range: 0 to the 98th percentile of valid cells, rounded up to 5 mm.
  std::vector<float> valid;
  for (std::size_t i = 0; i < values.size(); ++i)
    if (invalid[i] == 0) valid.push_back(values[i]);
  double vmax = 10.0;
  if (!valid.empty()) {
    std::nth_element(valid.begin(), valid.begin() + valid.size() * 98 / 100, valid.end());
    vmax = std::max(5.0, std::ceil(valid[valid.size() * 98 / 100] / 5.0) * 5.0);
  }
  RgbImage map = make_image(fig.map_w, fig.map_h);
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const std::size_t c = g.index(j, k);
      for (int dy = 0; dy < s; ++dy)
        for (int dx = 0; dx < s; ++dx) {
          const int x = j * s + dx, y = (g.n_z - 1 - k) * s + dy;
          if (maps.flags[c] & kNoSkin) continue;  // stays white
          map.set(x, y, invalid[c] != 0 ? hatch(x, y) : viridis(values[c] / vmax));
        }
    }
  fig.canvas.draw_image(map, MapFigure::kLeft, MapFigure::kTop);
  fig.axes_and_title(title);
  // Colour bar.
  const int bx = MapFigure::kLeft + fig.map_w + 30, bw = 22, by = MapFigure::kTop, bh = fig.map_h;
  fig.canvas.colour_bar(bx, by, bw, bh);
  const double tick = vmax <= 10 ? 2.0 : (vmax <= 30 ? 5.0 : 10.0);
  for (double v = 0; v <= vmax + 1e-9; v += tick) {
    const double y = by + bh - 1 - v / vmax * (bh - 1);
    fig.tick(bx + bw, y, bx + bw + 5, y);
    fig.text(bx + bw + 8, y + 4, cat(static_cast<int>(v), " mm"), 11);
  }
  fig.text(bx + bw + 60, by + 0.5 * bh, bar_label, 12, 0.5, -90);
  // Legend for invalid cells, and the credit line.
  const int ly = MapFigure::kTop + fig.map_h + 52;
  RgbImage swatch = make_image(18, 10);
  for (int y = 0; y < swatch.height; ++y)
    for (int x = 0; x < swatch.width; ++x) swatch.set(x, y, hatch(x, y));
  fig.canvas.draw_image(swatch, MapFigure::kLeft, ly - 9);
  fig.text(MapFigure::kLeft + 24, ly, legend, 11);
  if (!credit.empty())
    fig.text(MapFigure::kLeft + fig.map_w + MapFigure::kRight - 10, ly, credit, 10, 1.0);
  fig.canvas.write_png(path);
}

}  // namespace

void write_thickness_png(const fs::path& path, const CylindricalMaps& maps,
                         const std::vector<float>& values, const std::string& title,
                         const std::string& credit) {
  // Cells over an air cavity (kBaseCavity) are measured: only the invalid ones are hatched.
  std::vector<std::uint8_t> invalid(maps.flags.size());
  for (std::size_t c = 0; c < invalid.size(); ++c) invalid[c] = maps.flags[c] & kInvalidFlags;
  write_mm_map_png(path, maps, values, invalid, "soft-tissue thickness (mm)",
                   "no valid measurement (no bone or cavity within the cap, undercut, grazing "
                   "ray, the eye; filled by interpolation)", title, credit);
}

void write_layer_png(const fs::path& path, const CylindricalMaps& maps,
                     const std::vector<float>& values, const std::vector<std::uint8_t>& layer_flags,
                     const std::string& what, const std::string& title,
                     const std::string& credit) {
  write_mm_map_png(path, maps, values, layer_flags, what,
                   "layer not measured (no valid thickness, no fat seen, fat in several bands, "
                   "skin not resolved; filled from neighbours' proportions)", title, credit);
}

void write_skin_png(const fs::path& path, const CylindricalMaps& maps, const std::string& title,
                    const std::string& credit) {
  const auto& g = maps.grid;
  // Lambert shading of the range surface, lit from the front, above and the viewer's side.
  const Eigen::Vector3d light = Eigen::Vector3d(0.3, 0.6, 1.0).normalized();  // (left, up, out)
  const double dth = deg_to_rad(g.dtheta_deg());
  const Eigen::Vector3d tone(0.93, 0.76, 0.65);
  RgbImage cells = make_image(g.n_theta, g.n_z);
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const std::size_t c = g.index(j, k);
      if (maps.flags[c] & kNoSkin) continue;  // stays white
      const int jl = (j + g.n_theta - 1) % g.n_theta, jr = (j + 1) % g.n_theta;
      const int kd = std::max(0, k - 1), ku = std::min(g.n_z - 1, k + 1);
      const double r = maps.r_skin[c];
      const double dr_dth = (maps.r_skin[g.index(jr, k)] - maps.r_skin[g.index(jl, k)]) / (2 * dth);
      const double dr_dz = (maps.r_skin[g.index(j, ku)] - maps.r_skin[g.index(j, kd)]) /
                           ((ku - kd) * g.dz_mm);
      // Normal in the local (tangential, axial, radial) frame of the cylinder.
      const Eigen::Vector3d n = Eigen::Vector3d(-dr_dth / std::max(r, 1.0), -dr_dz, 1.0).normalized();
      cells.set(j, g.n_z - 1 - k, tone * (0.25 + 0.75 * std::max(0.0, n.dot(light))));
    }
  write_map_png(path, g, cells, title, credit);
}

void write_map_png(const fs::path& path, const CylinderGrid& g, const RgbImage& cells,
                   const std::string& title, const std::string& credit) {
  if (cells.width != g.n_theta || cells.height != g.n_z ||
      cells.rgb.size() != std::size_t(cells.width) * cells.height * 3)
    throw InvalidInput(cat(path.string(), ": the picture is ", cells.width, " x ", cells.height,
                           " pixels, expected the grid's ", g.n_theta, " x ", g.n_z));
  MapFigure fig(g);
  fig.canvas.draw_image(cells, MapFigure::kLeft, MapFigure::kTop, fig.scale);
  fig.axes_and_title(title);
  if (!credit.empty()) fig.text(MapFigure::kLeft, MapFigure::kTop + fig.map_h + 56, credit, 10);
  fig.canvas.write_png(path);
}

}  // namespace caps

#include "caps/render/sensitivity_picture.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/image/canvas.hpp"
#include "caps/render/overlay.hpp"
#include "caps/render/render.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/surface/range_mesh.hpp"

namespace caps::render {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double change_of(const study::SensitivityPoint& p, bool force) {
  return force ? p.force_change : p.displacement_change;
}

// A colour scale in percent: at least 10 %, else the 95th percentile of |change| rounded up to
// 10, 20, 25, 50 or 100 x a power of ten.
double scale_percent(const study::SensitivityMap& map) {
  std::vector<double> a;
  for (const auto& p : map.points)
    if (p.planned) {
      a.push_back(100 * std::abs(p.force_change));
      a.push_back(100 * std::abs(p.displacement_change));
    }
  if (a.empty()) return 10;
  const std::size_t i = std::min(a.size() - 1, static_cast<std::size_t>(0.95 * (a.size() - 1) + 0.5));
  std::nth_element(a.begin(), a.begin() + i, a.end());
  const double raw = std::max(10.0, a[i]);
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 2.5, 5.0, 10.0})
    if (m * mag >= raw - 1e-9) return m * mag;
  return 10 * mag;
}

}  // namespace

double sensitivity_at(const study::SensitivityMap& map, double theta_deg, double z_mm, bool force) {
  const int nt = static_cast<int>(map.theta_deg.size()), nz = static_cast<int>(map.z_mm.size());
  if (nt == 0 || nz == 0) return kNaN;
  const double dt = nt > 1 ? map.theta_deg[1] - map.theta_deg[0] : 1.0;
  const double dz = nz > 1 ? map.z_mm[1] - map.z_mm[0] : 1.0;
  const double fi = (theta_deg - map.theta_deg[0]) / dt, fk = (z_mm - map.z_mm[0]) / dz;
  if (fi < -0.5 || fi > nt - 0.5 || fk < -0.5 || fk > nz - 0.5) return kNaN;
  auto at = [&](int i, int k) -> const study::SensitivityPoint& { return map.points[std::size_t(k) * nt + i]; };
  if (nt > 1 && nz > 1 && fi >= 0 && fi <= nt - 1 && fk >= 0 && fk <= nz - 1) {
    const int i = std::min(static_cast<int>(std::floor(fi)), nt - 2);
    const int k = std::min(static_cast<int>(std::floor(fk)), nz - 2);
    const double a = fi - i, b = fk - k;
    const auto &p00 = at(i, k), &p10 = at(i + 1, k), &p01 = at(i, k + 1), &p11 = at(i + 1, k + 1);
    if (p00.planned && p10.planned && p01.planned && p11.planned)
      return (1 - a) * (1 - b) * change_of(p00, force) + a * (1 - b) * change_of(p10, force) +
             (1 - a) * b * change_of(p01, force) + a * b * change_of(p11, force);
  }
  const int i = std::clamp(static_cast<int>(std::lround(fi)), 0, nt - 1);
  const int k = std::clamp(static_cast<int>(std::lround(fk)), 0, nz - 1);
  return at(i, k).planned ? change_of(at(i, k), force) : kNaN;
}

RgbImage sensitivity_picture(const study::SensitivityMap& map, const PatientModel& model,
                             const std::string& title, const std::string& credit, int panel_px) {
  if (panel_px < 200 || panel_px > 4000)
    throw InvalidInput(cat("sensitivity picture: panel size ", panel_px, " px must be in [200, 4000]"));
  const CylinderAxis& axis = model.axis();
  const CylinderGrid& g = model.grid();
  const TriMesh skin = range_mesh(model.maps(), RangeSurface::Skin);
  // Frame the mapped region from the front.
  Camera cam;
  cam.projection = Projection::Orthographic;
  cam.forward = -axis.front;
  cam.up = axis.direction;
  cam.width_px = cam.height_px = panel_px;
  const Eigen::Vector3d right = cam.forward.cross(cam.up);
  Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
  for (double t : map.theta_deg)
    for (double z : map.z_mm) {
      const Eigen::Vector3d p = model.skin_point(t, z);
      lo = lo.cwiseMin(Eigen::Vector2d(p.dot(right), p.dot(cam.up)));
      hi = hi.cwiseMax(Eigen::Vector2d(p.dot(right), p.dot(cam.up)));
    }
  const Eigen::Vector2d mid = 0.5 * (lo + hi);
  const Eigen::Vector3d centre = model.skin_point(0.0, 0.5 * (map.z_mm.front() + map.z_mm.back()));
  cam.target = centre + (mid.x() - centre.dot(right)) * right + (mid.y() - centre.dot(cam.up)) * cam.up;
  cam.width_mm = 1.2 * std::max({hi.x() - lo.x(), hi.y() - lo.y(), 20.0});
  double radius = 0;
  for (Eigen::Index v = 0; v < skin.V.rows(); ++v) radius = std::max(radius, (skin.V.row(v).transpose() - cam.target).norm());
  cam.distance_mm = 2 * radius + 10;
  const double top = scale_percent(map);
  RenderOptions ro;
  ro.background = {1, 1, 1};
  const int bar_w = std::max(220, panel_px / 4), head = 70, foot = 60;
  Canvas canvas(2 * panel_px + bar_w, panel_px + head + foot);
  const double font = std::max(14.0, 0.02 * panel_px);
  for (int side = 0; side < 2; ++side) {
    const bool force = side == 0;
    Eigen::MatrixX3d colour(skin.V.rows(), 3);
    for (Eigen::Index v = 0; v < skin.V.rows(); ++v) {
      double c = kNaN;
      if (v < static_cast<Eigen::Index>(g.size())) {
        const int j = static_cast<int>(v % g.n_theta), k = static_cast<int>(v / g.n_theta);
        c = sensitivity_at(map, std::remainder(g.theta_deg(j), 360.0), g.z_mm(k), force);
      }
      if (std::isfinite(c))
        colour.row(v) = signed_colour(100 * c / top).transpose();
      else
        colour.row(v) << 0.72, 0.70, 0.68;
    }
    const RgbImage panel = render_image(skin, colour, cam, ro);
    const int x0 = side * panel_px;
    canvas.draw_image(panel, x0, head);
    for (const auto& p : map.points) {
      const Eigen::Vector3d s = model.skin_point(p.theta_deg, p.z_mm);
      if (model.skin_normal(p.theta_deg, p.z_mm).dot(-cam.forward.normalized()) < 0.15) continue;
      const Eigen::Vector2d q = cam.project(s) + Eigen::Vector2d(x0, head);
      if (p.planned) {
        canvas.fill_circle(q, 2.5, {0.1, 0.1, 0.1});
      } else {
        const Pen pen{.colour = {0.1, 0.1, 0.1}, .width_px = 2.0};
        canvas.line(q + Eigen::Vector2d(-5, -5), q + Eigen::Vector2d(5, 5), pen);
        canvas.line(q + Eigen::Vector2d(-5, 5), q + Eigen::Vector2d(5, -5), pen);
      }
    }
    const TextStyle label{.size_px = font * 1.1, .align = 0.5, .halo = true};
    canvas.text(x0 + 0.5 * panel_px, head - 12,
                force ? "closing force: constant vs measured" : "largest displacement: constant vs measured", label);
  }
  // The colour bar.
  const double bx = 2 * panel_px + 30, by = head + 0.2 * panel_px, bw = 22, bh = 0.6 * panel_px;
  canvas.colour_bar(bx, by, bw, bh, [](double t) { return signed_colour(2 * t - 1); });
  canvas.stroke_rect(bx, by, bw, bh, Pen{.colour = {0.4, 0.4, 0.4}, .width_px = 0.5});
  const TextStyle tick{.size_px = font};
  for (int k = -2; k <= 2; ++k) {
    const double v = k * top / 2, y = by + bh / 2 - v / top * bh / 2;
    canvas.line(Eigen::Vector2d(bx + bw, y), Eigen::Vector2d(bx + bw + 5, y));
    char buf[32];
    std::snprintf(buf, sizeof buf, "%s%.*f %%", v > 0 ? "+" : "", top >= 20 ? 0 : 1, v);
    canvas.text(bx + bw + 8, y + 0.35 * font, buf, tick);
  }
  canvas.text(bx - 10, by - 2.6 * font, "constant thickness", tick);
  canvas.text(bx - 10, by - 1.4 * font, "overestimates", tick);
  canvas.text(bx - 10, by + bh + 1.6 * font, "underestimates", tick);
  char cbuf[160];
  std::snprintf(cbuf, sizeof cbuf, "constant %.1f mm", map.constant_thickness_mm);
  canvas.text(bx - 10, by + bh + 3.4 * font, cbuf, tick);
  canvas.text(bx - 10, by + bh + 4.6 * font, "dot: plan centre", tick);
  canvas.text(bx - 10, by + bh + 5.8 * font, "cross: cannot plan", tick);
  canvas.text(bx - 10, by + bh + 7.0 * font, "grey: not mapped", tick);
  canvas.text(12, 1.4 * font, title, TextStyle{.size_px = font * 1.2});
  std::snprintf(cbuf, sizeof cbuf, "white: a scan alone is enough; colour: the CT's thickness changes the result "
                "(%d of %zu centres planned)", map.planned, map.points.size());
  canvas.text(12, panel_px + head + 1.6 * font, cbuf, tick);
  if (!credit.empty()) canvas.text(12, panel_px + head + 3.0 * font, credit, tick);
  return canvas.image();
}

}  // namespace caps::render

#include "caps/plan/plan_figure.hpp"

#include <algorithm>
#include <cmath>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/image/canvas.hpp"
#include "caps/image/colormap.hpp"

namespace fs = std::filesystem;

namespace caps::plan {

namespace {

using V2 = Eigen::Vector2d;

const Eigen::Vector3d kRed(0.85, 0.1, 0.1), kBlue(0.1, 0.25, 0.85), kInk(0.1, 0.1, 0.1);

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
  Canvas canvas(left + W + right, top + H + bottom);
  auto text = [&](double x, double y, const std::string& t, double size, double align = 0.0,
                  const Eigen::Vector3d& colour = kInk, bool halo = false) {
    canvas.text(x, y, t, {.size_px = size, .colour = colour, .align = align, .halo = halo});
  };

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
  RgbImage map = make_image(W, H);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const V2 tz = plan.frame.to_theta_z(local(V2(lo.x() + (x + 0.5) / ppm, hi.y() - (y + 0.5) / ppm)));
      Eigen::Vector3d c = colour ? model.color_at(tz[0], tz[1]) : viridis(model.thickness(tz[0], tz[1]) / vmax);
      if (!model.has_z(tz[1]) || !flags_valid(model.flags_at(tz[0], tz[1])))
        c = ((x + y) / 4) % 2 ? Eigen::Vector3d(0.75, 0.75, 0.75) : Eigen::Vector3d(0.9, 0.9, 0.9);
      map.set(x, y, c);
    }
  canvas.draw_image(map, left, top);
  auto px = [&](const V2& xy) -> V2 {
    const V2 p = pic(xy);
    return {left + (p.x() - lo.x()) * ppm, top + (hi.y() - p.y()) * ppm};
  };

  // The hole (excised tissue) and its border loop.
  std::vector<V2> hole(n);
  for (int i = 0; i < n; ++i) hole[i] = px(loop.local_mm[i]);
  canvas.fill_polygon(hole, kRed, 0.25);
  canvas.polyline(hole, {.colour = kRed, .width_px = 2.0, .round_joins = true}, true);
  // The surgeon's cutting paths, thin and dashed over the loop.
  for (const auto& path : plan.paths) {
    std::vector<V2> line;
    for (int k : path) {
      const auto& s = plan.points[k];
      line.push_back(px(plan.frame.to_local(s.theta_deg, s.z_mm)));
    }
    canvas.polyline(line, {.colour = {0.05, 0.05, 0.05}, .width_px = 1.2, .dash_px = {5.0, 3.0},
                           .round_joins = true});
  }

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
    canvas.fill_circle(p, 2.5, kRed);
    const V2 t = p + 13.0 * side[i];
    text(t.x(), t.y() + 4, std::to_string(i), 13, 0.5, {0.6, 0.0, 0.0}, true);
  }
  // Sutures: dashed blue lines join the nodes that meet; each pair labelled at its two edges.
  const Pen dotted{.colour = kBlue, .width_px = 1.2, .dash_px = {2.0, 3.0}};
  for (std::size_t k = 0; k < plan.sutures.size(); ++k) {
    const auto q = oriented_suture(plan.sutures[k], n);
    for (auto [u, v] : {std::pair{q[0], q[2]}, std::pair{q[1], q[3]}}) {
      if (u == v) {  // a corner being closed
        canvas.stroke_circle(px(loop.local_mm[u]), 6, {.colour = kBlue, .width_px = 1.2});
        continue;
      }
      canvas.line(px(loop.local_mm[u]), px(loop.local_mm[v]), dotted);
    }
    const auto edges = suture_edges(q, n);
    for (int e : {edges[0][edges[0].size() / 2], edges[1][edges[1].size() / 2]}) {
      const V2 a = px(loop.local_mm[e]), b = px(loop.local_mm[(e + 1) % n]);
      if ((b - a).norm() < 36) continue;  // too short to label legibly; the list below has it
      const V2 d = (b - a).normalized();
      const V2 m = 0.5 * (a + b) + 9.0 * V2(d.y(), -d.x());
      text(m.x(), m.y() + 4, cat("s", k), 11, 0.5, kBlue, true);
    }
  }
  // Scale bar (10 mm), frame, title and legend.
  canvas.line(V2(left + 8, top + H - 10), V2(left + 8 + 10 * ppm, top + H - 10), {.width_px = 3});
  text(left + 8 + 5 * ppm, top + H - 16, "10 mm", 11, 0.5, kInk, true);
  canvas.stroke_rect(left - 0.5, top - 0.5, W + 1, H + 1);
  std::string params;
  for (const auto& [k, v] : plan.parameters) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%s%s %.4g", params.empty() ? "" : ", ", k.c_str(), v);
    params += buf;
  }
  char where[128];
  std::snprintf(where, sizeof where, "at theta %.1f deg, z %.1f mm, orientation %.0f deg",
                plan.frame.theta_deg, plan.frame.z_mm, plan.frame.orientation_deg);
  text(left, 18, cat(plan.procedure, params.empty() ? "" : " (" + params + ")"), 14);
  text(left, 34, cat(where, "; superior up, patient's left to the right; ",
                         colour ? "skin colour" : cat("thickness 0-", vmax, " mm (viridis)")), 11);
  const int ly = top + H + 18;
  text(left, ly, "red: border loop, node numbers on their tissue side; black dashed: cutting path", 10.5);
  text(left, ly + 14, "blue dashed: nodes brought together; blue circle: corner closed; sK: suture "
                          "pair K; grey hatching: invalid cells", 10.5);
  std::string line;
  int row = 0;
  for (std::size_t k = 0; k < plan.sutures.size(); ++k) {
    const auto& s = plan.sutures[k];
    line += cat("s", k, " = ", suture_text(s), "   ");
    if (k % 3 == 2 || k + 1 == plan.sutures.size()) {
      text(left, ly + 32 + 16 * row++, line, 11, 0, kBlue);
      line.clear();
    }
  }
  canvas.write_png(path);
}

}  // namespace caps::plan
